// Steps a SlamCoordinator by hand until it is out of work (it has then integrated what waits,
// run what it owes and published what changed): the SLAM suites that drive mapping themselves.
#pragma once

#include <gtest/gtest.h>

#include "core/slam/slam_coordinator.h"

namespace plx::testing {

// Fails the calling test on a step's error, or when mapping never runs out of work.
inline void RunMappingOut(SlamCoordinator& coordinator,
                          SlamStepMode mode = SlamStepMode::kMap) {
  for (int i = 0; i < 100000; ++i) {
    absl::StatusOr<SlamStepResult> step = coordinator.Step(mode);
    ASSERT_TRUE(step.ok()) << step.status();
    if (step->out_of_work) return;
  }
  FAIL() << "mapping never ran out of work";
}

}  // namespace plx::testing
