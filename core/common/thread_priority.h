// Lowering one thread's CPU priority, so that on a shared CPU its work takes the cycles other
// threads leave over (mapping beside tracking: in-process SLAM's mapping thread, the daemon's
// CPU mapping worker and their thread pools).
//
// On Linux a nice value belongs to a thread, not to the process (setpriority on the thread id),
// and a thread starts with its creator's value: a pool started from a lowered thread inherits
// it. Raising the nice value needs no privilege; lowering it back would, so it only goes up.
// Under the kernel's fair scheduler a thread at nice n gets about 1.25^-n of the share of a
// nice-0 thread when both want the core: at 10 about a tenth.
#pragma once

#include "absl/status/status.h"

namespace plx {

// Adds `increment` (0-19) to the calling thread's nice value, capped at 19. 0 does nothing.
// INVALID_ARGUMENT outside 0-19; INTERNAL with the system's reason when the system refuses.
absl::Status LowerCurrentThreadPriority(int increment);

// The calling thread's nice value (for tests and logs).
int CurrentThreadNice();

}  // namespace plx
