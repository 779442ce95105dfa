#include "core/mapping/mapping_session.h"

#include <algorithm>
#include <chrono>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/allocation_guard.h"
#include "core/common/status_macros.h"
#include "core/geometry/world_pose.h"

namespace plx {
namespace {

double NowSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

absl::Status ValidateMappingSessionOptions(const MappingSessionOptions& o) {
  if (o.iterations_per_keyframe <= 0 || o.iterations_per_keyframe > kMaxIterationsPerKeyframe) {
    return absl::InvalidArgumentError(absl::StrCat("iterations_per_keyframe must be in [1, ",
                                                   kMaxIterationsPerKeyframe, "], got ",
                                                   o.iterations_per_keyframe));
  }
  if (o.chunk_iterations <= 0 || !(o.chunk_seconds > 0.0)) {
    return absl::InvalidArgumentError("a mapping step needs positive chunk limits");
  }
  if (o.iterations_after_integration < 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "iterations_after_integration must be at least 1, got ", o.iterations_after_integration));
  }
  if (o.max_clones_per_iteration < 0) {
    return absl::InvalidArgumentError("max_clones_per_iteration must not be negative");
  }
  if (!(o.min_publish_interval_s >= 0.0) || o.publish_every_iterations <= 0) {
    return absl::InvalidArgumentError("publish interval and cadence must be positive");
  }
  MapperOptions mapper = o.mapper;
  mapper.max_iterations = o.iterations_per_keyframe;  // the session sets the budget
  mapper.time_budget_s = 0.0;
  return Mapper::ValidateOptions(mapper);
}

absl::StatusOr<std::unique_ptr<MappingSession>> MappingSession::Create(
    const MappingSessionOptions& options, Backend* backend,
    std::shared_ptr<const PlenoxelMap> base) {
  PLX_RETURN_IF_ERROR(ValidateMappingSessionOptions(options));
  MapperOptions mapper_options = options.mapper;
  mapper_options.max_iterations = options.iterations_per_keyframe;
  mapper_options.time_budget_s = 0.0;
  mapper_options.max_clones_per_iteration = options.max_clones_per_iteration;
  // Keyframes stream in: coarse-to-fine would have to re-allocate from every keyframe.
  mapper_options.coarse_to_fine = false;
  return CatchAllocationFailure(
      "starting a mapping session", [&]() -> absl::StatusOr<std::unique_ptr<MappingSession>> {
        std::unique_ptr<Mapper> mapper;
        if (base != nullptr) {
          // Copy-on-write: the session's map shares every brick with `base` until it changes
          // one, so continuing a large map costs its index, not its bricks.
          mapper = std::make_unique<Mapper>(mapper_options, backend,
                                            std::make_unique<PlenoxelMap>(base->ShareCopy()));
        } else {
          mapper = std::make_unique<Mapper>(mapper_options, backend);
        }
        std::unique_ptr<MappingSession> session(new MappingSession(options, std::move(mapper)));
        session->latest_ = std::move(base);
        return session;
      });
}

MappingSession::MappingSession(const MappingSessionOptions& options,
                               std::unique_ptr<Mapper> mapper)
    : options_(options), mapper_(std::move(mapper)) {}

absl::Status MappingSession::AddKeyframe(RgbdFrame frame, const SE3& world_T_camera,
                                         const PinholeIntrinsics& k, bool earns_iterations) {
  if (frame.color.width != k.width || frame.color.height != k.height ||
      frame.depth.width != k.width || frame.depth.height != k.height ||
      frame.color.channels != 3 || frame.depth.channels != 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "keyframe images (colour ", frame.color.width, "x", frame.color.height, "x",
        frame.color.channels, ", depth ", frame.depth.width, "x", frame.depth.height, "x",
        frame.depth.channels, ") do not match the intrinsics (", k.width, "x", k.height, ")"));
  }
  PLX_RETURN_IF_ERROR(CheckPoseInsideWorld(world_T_camera, "keyframe pose"));
  std::lock_guard<std::mutex> lock(mutex_);
  pending_.push_back(PendingKeyframe{std::move(frame), world_T_camera, k, earns_iterations});
  ++added_;
  return absl::OkStatus();
}

int MappingSession::pending_keyframes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(pending_.size());
}

bool MappingSession::BudgetLeft() const {
  // Mapper::budget_spent reads a zero budget as "no limit": here it is none.
  return integrated_ > 0 && Budget() > 0 && mapper_->training_set().num_rays() > 0 &&
         !mapper_->budget_spent();
}

int MappingSession::Budget() const {
  return options_.iterations_per_keyframe * earning_integrated_ + granted_iterations_;
}

void MappingSession::GrantIterations(int iterations) {
  if (iterations <= 0) return;
  granted_iterations_ += iterations;
  mapper_->set_max_iterations(Budget());
}

bool MappingSession::has_work() const {
  return mapper_->integrating() || pending_keyframes() > 0 || BudgetLeft();
}

absl::StatusOr<MappingStepResult> MappingSession::Step(bool finish) {
  return CatchAllocationFailure("mapping step", [&]() -> absl::StatusOr<MappingStepResult> {
    MappingStepResult result;
    std::optional<PendingKeyframe> next;
    // A keyframe just integrated gets its iterations_after_integration before the next queued
    // keyframe starts (at least one chunk, the order of work before integration was sliced),
    // so a queue of keyframes does not hold the optimisation back and the region it added is
    // fitted before trackers see it.
    const bool chunk_first = owed_after_integration_ > 0 && BudgetLeft();
    if (!chunk_first) owed_after_integration_ = 0;
    if (!mapper_->integrating() && !chunk_first) {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!pending_.empty()) {
        next = std::move(pending_.front());
        pending_.pop_front();
      }
    }
    if (next) {
      integrating_earns_ = next->earns_iterations;
      PLX_RETURN_IF_ERROR(
          mapper_->AddKeyframe(std::move(next->frame), next->world_T_camera, next->intrinsics));
    }
    if (next || mapper_->integrating()) {
      // A step is one slice of a keyframe's integration or one optimisation chunk, not both:
      // either is bounded by chunk_seconds, so a tracking frame waits for one of them.
      PLX_RETURN_IF_ERROR(IntegrateSlice(options_.chunk_seconds, &result));
    } else if (BudgetLeft()) {
      const double start = NowSeconds();
      const int before = mapper_->iterations_done();
      PLX_ASSIGN_OR_RETURN(
          MappingSummary summary,
          mapper_->Optimize([](const MappingProgress&) { return true; },
                            options_.chunk_iterations, options_.chunk_seconds));
      last_ = summary.last;
      result.iterations = mapper_->iterations_done() - before;
      owed_after_integration_ = std::max(0, owed_after_integration_ - result.iterations);
      changed_since_publish_ = changed_since_publish_ || result.iterations > 0;
      result.optimize_s = NowSeconds() - start;
    }

    // Never in the middle of an integration (Mapper::Publish would finish it in this step), nor
    // between an integration and its first chunk: the version comes after that chunk, as it did
    // when both ran in one step (publishing first would make the chunk clone, or with a clone
    // cap defer, the bricks it writes).
    const bool chunk_follows = owed_after_integration_ > 0 && BudgetLeft();
    if (!mapper_->integrating() && !chunk_follows) {
      const double now = NowSeconds();
      const double gap = std::max(options_.min_publish_interval_s, 10.0 * last_publish_cost_s_);
      const bool enough_new = keyframes_since_publish_ > 0 ||
                              mapper_->iterations_done() - iterations_at_publish_ >=
                                  options_.publish_every_iterations;
      const bool due = changed_since_publish_ && now - last_publish_time_s_ >= gap && enough_new;
      const bool final_version = finish && changed_since_publish_ && !has_work();
      if (due || final_version) PLX_RETURN_IF_ERROR(PublishInto(&result));
    }
    return result;
  });
}

absl::Status MappingSession::IntegrateSlice(double max_seconds, MappingStepResult* result) {
  const double start = NowSeconds();
  PLX_ASSIGN_OR_RETURN(const bool done, mapper_->IntegrateSlice(max_seconds));
  result->integrate_s += NowSeconds() - start;
  if (!done) return absl::OkStatus();
  ++integrated_;
  if (integrating_earns_) ++earning_integrated_;
  ++keyframes_since_publish_;
  changed_since_publish_ = true;
  mapper_->set_max_iterations(Budget());
  result->keyframes_integrated = 1;
  owed_after_integration_ = options_.iterations_after_integration;
  return absl::OkStatus();
}

absl::Status MappingSession::PublishInto(MappingStepResult* result) {
  const double start = NowSeconds();
  PLX_ASSIGN_OR_RETURN(latest_, mapper_->Publish());
  last_publish_time_s_ = NowSeconds();
  last_publish_cost_s_ = last_publish_time_s_ - start;
  result->published = latest_;
  result->keyframes_in_published = keyframes_since_publish_;
  result->publish_s = last_publish_cost_s_;
  ++published_versions_;
  changed_since_publish_ = false;
  keyframes_since_publish_ = 0;
  iterations_at_publish_ = mapper_->iterations_done();
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<const PlenoxelMap>> MappingSession::Publish() {
  MappingStepResult ignored;
  // The keyframe being integrated goes into this version whole (a save waits for it).
  if (mapper_->integrating()) PLX_RETURN_IF_ERROR(IntegrateSlice(0.0, &ignored));
  if (!changed_since_publish_ && latest_ != nullptr) return latest_;
  PLX_RETURN_IF_ERROR(CatchAllocationFailure("publishing the map",
                                             [&] { return PublishInto(&ignored); }));
  return latest_;
}

absl::Status MappingSession::SetKeyframePose(int i, const SE3& world_T_camera) {
  PLX_RETURN_IF_ERROR(mapper_->SetKeyframePose(i, world_T_camera));
  changed_since_publish_ = true;
  return absl::OkStatus();
}

MappingSessionProgress MappingSession::progress() const {
  MappingSessionProgress p;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    p.keyframes_added = added_;
  }
  p.keyframes_integrated = integrated_;
  p.iterations = mapper_->iterations_done();
  p.iteration_budget = Budget();
  p.fraction = p.iteration_budget > 0
                   ? std::min(1.0, static_cast<double>(p.iterations) / p.iteration_budget)
                   : 0.0;
  p.schedule = mapper_->schedule_fraction();
  p.last_batch = last_;
  p.published_versions = published_versions_;
  p.map_bytes = mapper_->map().grid.Memory().total_bytes();
  p.cloned_bricks = mapper_->summary().cloned_bricks;
  p.last_publish_s = last_publish_cost_s_;
  return p;
}

}  // namespace plx
