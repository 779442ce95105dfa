#include "core/slam/slam_coordinator.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/mapping/map_keyframes_of.h"
#include "core/slam/slam_session.h"

namespace plx {

void ApplyLockStepMappingPolicy(SlamMapperOptions* options) {
  options->mapping.min_publish_interval_s = 1e9;
  options->mapping.max_clones_per_iteration = 0;
  // A chunk cut by wall time holds a different number of iterations on a loaded machine, and a
  // rebuild's keyframes interleave with its chunks and swap in after a count of iterations: the
  // map would differ run to run. Lock-step chunks by iterations only.
  options->mapping.chunk_seconds = kLockStepUnreachedSeconds;
  // Likewise the pose-graph solve stops at its iteration bound only (a loaded CI run stopped
  // early by wall time replaced 2 sequential edges where an idle run replaces none).
  options->loop_closure.graph.max_solve_seconds = kLockStepUnreachedSeconds;
}

SlamSplitOptions SplitSlamOptions(const SlamOptions& o) {
  SlamSplitOptions out;
  out.tracker.tracker = o.tracker;
  out.tracker.keyframes = o.keyframes;
  out.tracker.relocalisation_keyframes = o.relocalisation_keyframes;
  out.tracker.relocalisation_radius_m = o.relocalisation_radius_m;
  out.tracker.odometry = o.odometry;
  out.tracker.feature_relocalisation = o.feature_relocalisation;
  out.tracker.new_segment_after_lost_frames = o.new_segment_after_lost_frames;
  out.tracker.new_segment_after_unconfirmed_frames = o.new_segment_after_unconfirmed_frames;
  out.tracker.segment_join_interval = o.segment_join_interval;
  // Lock-step maps keyframe 0 before the next frame: nothing to carry (and no timing).
  if (o.deterministic) out.tracker.max_seconds_without_map = 0.0;
  out.tracker.map_time_budget = o.deterministic ? 0.0 : o.map_time_budget;
  // Lock-step maps every keyframe before the next frame: nothing is ever left pending.
  out.tracker.max_pending_keyframes = o.deterministic ? 0 : o.max_pending_keyframes;
  out.tracker.initial_pose = o.initial_pose;
  if (o.live_source) {
    // No frame waits for mapping: not for a keyframe's room, not for the first version.
    out.tracker.max_deferred_frames = 0;
    out.tracker.carry_until_version = true;
  }
  // A pixel helps the bootstrap only if the tracker uses it and the mapper maps it.
  out.tracker.bootstrap_max_depth =
      std::min(o.tracker.params.max_depth, o.mapping.mapper.allocation.max_depth);

  out.mapper.mapping = o.mapping;
  out.mapper.refinement = o.refinement;
  out.mapper.loop_closure = o.loop_closure;
  if (o.deterministic) ApplyLockStepMappingPolicy(&out.mapper);

  out.gate.lock_step = o.deterministic;
  out.gate.max_pending_keyframes = out.tracker.max_pending_keyframes;
  return out;
}

SlamCoordinator::SlamCoordinator(const SlamMapperOptions& mapper_options,
                                 const SlamGateOptions& gate,
                                 std::shared_ptr<const PlenoxelMap> base, int64_t base_version,
                                 SlamPublisher publisher)
    : mapper_options_(mapper_options), gate_(gate), publisher_(std::move(publisher)) {
  if (base != nullptr && base->grid.num_bricks() == 0) base = nullptr;  // nothing to extend
  base_ = base;
  auto main = std::make_unique<Segment>();
  main->published = {std::move(base), base_version};
  main->progress.map_version = base_version;
  segments_.push_back(std::move(main));
}

template <typename T>
std::vector<T> SlamCoordinator::AfterSaved(const std::vector<T>& saved, std::vector<T> rest) {
  if (saved.empty()) return rest;
  std::vector<T> out;
  out.reserve(saved.size() + rest.size());
  out.insert(out.end(), saved.begin(), saved.end());
  out.insert(out.end(), std::make_move_iterator(rest.begin()),
             std::make_move_iterator(rest.end()));
  return out;
}

absl::Status SlamCoordinator::SeedSavedKeyframes(MapKeyframes saved) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Segment& main = *segments_[0];
  if (started_ || main.progress.keyframes > 0 || !saved_.empty()) {
    return absl::FailedPreconditionError(
        "saved keyframes are seeded once, before the mapper starts and any keyframe comes");
  }
  if (base_ == nullptr) {
    return absl::FailedPreconditionError(
        "saved keyframes belong to a base map, and this coordinator has none");
  }
  for (const MapKeyframe& k : saved) {
    saved_poses_.push_back({k.timestamp, k.pose});
    saved_features_.push_back(k.features);
  }
  saved_ = std::move(saved);
  published_keyframes_ = std::make_shared<const MapKeyframes>(saved_);
  return absl::OkStatus();
}

void SlamCoordinator::SetPublishedKeyframes(const SlamMapper& mapper) {
  MapKeyframes integrated = MapKeyframesOf(mapper.integrated_keyframes());
  std::lock_guard<std::mutex> lock(mutex_);
  // Keyframe i of the mapper is features[i]: both are in the order the keyframes were added.
  const std::vector<std::shared_ptr<const FrameFeatures>>& features = segments_[0]->features;
  for (size_t i = 0; i < integrated.size() && i < features.size(); ++i) {
    integrated[i].features = features[i];
  }
  published_keyframes_ =
      std::make_shared<const MapKeyframes>(AfterSaved(saved_, std::move(integrated)));
}

std::shared_ptr<const MapKeyframes> SlamCoordinator::published_keyframes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return published_keyframes_;
}

bool SlamCoordinator::mapper_started() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return started_;
}

absl::Status SlamCoordinator::StartMapper(Backend* backend) {
  if (mapper_started()) return absl::FailedPreconditionError("the SLAM mapper has started");
  PLX_ASSIGN_OR_RETURN(std::unique_ptr<SlamMapper> mapper,
                       SlamMapper::Create(mapper_options_, backend, base_));
  std::lock_guard<std::mutex> lock(mutex_);
  backend_ = backend;
  started_ = true;
  // Under the lock: a keyframe added meanwhile goes to `early` and is handed over here too, in
  // the order the cameras added them.
  Segment& main = *segments_[0];
  for (const EarlyKeyframe& k : main.early) {
    PLX_RETURN_IF_ERROR(mapper->AddKeyframe(k.frame, k.pose, k.intrinsics));
  }
  main.early.clear();
  main.mapper = std::move(mapper);
  return absl::OkStatus();
}

absl::Status SlamCoordinator::AddKeyframeLocked(const RgbdFrame& frame, const SE3& given_pose,
                                                const PinholeIntrinsics& k,
                                                std::shared_ptr<const FrameFeatures> features,
                                                const UnconfirmedMotion& unconfirmed,
                                                int camera, Segment* to, bool keep,
                                                int generation) {
  SE3 pose = given_pose;
  const bool main = to == segments_[0].get();
  const std::shared_ptr<const SlamCorrection> latest_correction = to->correction();
  if (main && latest_correction != nullptr && generation < latest_correction->generation) {
    pose = latest_correction->Move(pose);  // tracked before the camera saw the correction
  }
  if (to->mapper == nullptr) {
    // A mapper is made by the step-runner, with its backend (the daemon's first task).
    to->early.push_back({frame, pose, k});
    to->early.back().frame.ground_truth.reset();
  } else {
    PLX_RETURN_IF_ERROR(to->mapper->AddKeyframe(frame, pose, k));
  }
  if (main && to->rebuild_collecting) {
    to->rebuild_backlog.push_back({frame, pose, k});
    to->rebuild_backlog.back().frame.ground_truth.reset();
  } else if (main && to->rebuild != nullptr) {
    PLX_RETURN_IF_ERROR(to->rebuild->AddKeyframe(frame, to->rebuild_solve->Move(pose), k));
  }
  if (keep) {
    to->kept.push_back({frame, pose, k, camera});
    to->kept.back().frame.ground_truth.reset();
  }
  to->features.push_back(std::move(features));
  SequentialLink link;
  link.unconfirmed = unconfirmed;
  if (camera >= 0) {
    const auto last = to->last_keyframe_of_camera.find(camera);
    if (last != to->last_keyframe_of_camera.end()) link.from = last->second;
    to->last_keyframe_of_camera[camera] = static_cast<int>(to->links.size());
  }
  to->links.push_back(link);
  ++to->progress.keyframes;
  ++to->progress.pending_keyframes;
  to->has_work = true;
  to->progress.idle = false;
  return absl::OkStatus();
}

absl::Status SlamCoordinator::AddKeyframe(const RgbdFrame& frame, const SE3& pose,
                                          const PinholeIntrinsics& k,
                                          std::shared_ptr<const FrameFeatures> features,
                                          int segment, UnconfirmedMotion unconfirmed,
                                          int camera) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (segment < 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    return absl::InvalidArgumentError(absl::StrCat("no open map segment ", segment));
  }
  return AddKeyframeLocked(frame, pose, k, std::move(features), unconfirmed, camera,
                           segments_[segment].get(),
                           /*keep=*/segment != 0, CurrentGenerationLocked());
}

absl::Status SlamCoordinator::JoinLocked(int segment, const SE3& main_T_segment,
                                         int generation) {
  if (segment <= 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    return absl::InvalidArgumentError(absl::StrCat("no open map segment ", segment, " to join"));
  }
  Segment& from = *segments_[segment];
  // The poses mapping refined so far (integrated keyframes), else as accepted.
  const std::vector<StampedPose> refined =
      from.mapper != nullptr ? from.mapper->keyframe_poses() : std::vector<StampedPose>{};
  // A camera's chain in the main map ends where it lost the map: the segment's first keyframe
  // is tied to the main map by the join (the keyframe before it), not by tracking from the
  // camera's keyframe before the loss.
  Segment& main = *segments_[0];
  for (const auto& [camera, last] : from.last_keyframe_of_camera) {
    main.last_keyframe_of_camera.erase(camera);
  }
  for (size_t i = 0; i < from.kept.size(); ++i) {
    const SE3 pose = i < refined.size() ? refined[i].pose : from.kept[i].pose;
    PLX_RETURN_IF_ERROR(AddKeyframeLocked(from.kept[i].frame, main_T_segment * pose,
                                          from.kept[i].intrinsics, from.features[i],
                                          from.links[i].unconfirmed, from.kept[i].camera, &main,
                                          /*keep=*/false, generation));
  }
  from.joined = true;
  from.kept.clear();
  from.early.clear();
  from.has_work = false;
  ++segment_counts_.joined;
  return absl::OkStatus();
}

absl::StatusOr<bool> SlamCoordinator::Accept(const RgbdFrame& frame,
                                             const PinholeIntrinsics& k,
                                             SlamFrameResult* result, int* segment,
                                             int camera) {
  std::lock_guard<std::mutex> lock(mutex_);
  bool queued = false;
  if (result->new_segment) {
    segments_.push_back(std::make_unique<Segment>());
    *segment = static_cast<int>(segments_.size()) - 1;
    ++segment_counts_.started;
  } else if (result->main_T_segment && *segment != 0) {
    PLX_RETURN_IF_ERROR(
        JoinLocked(*segment, *result->main_T_segment, result->correction_generation));
    *segment = 0;
    queued = true;
  }
  result->segment = *segment;
  if (result->keyframe) {
    PLX_RETURN_IF_ERROR(AddKeyframeLocked(frame, result->pose, k, result->features,
                                          result->unconfirmed, camera,
                                          segments_[*segment].get(),
                                          /*keep=*/*segment != 0,
                                          result->correction_generation));
    queued = true;
  }
  return queued;
}

absl::StatusOr<SlamCoordinator::Segment*> SlamCoordinator::SegmentToStep(SlamStepMode mode,
                                                                          bool* main) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!started_) return absl::FailedPreconditionError("StartMapper before Step");
  // The main map, then segments, and only while cameras stream (finishing spends nothing on a
  // map that is not saved).
  const size_t count = mode == SlamStepMode::kMap ? segments_.size() : 1;
  for (size_t i = 1; i < count; ++i) {
    Segment& s = *segments_[i];
    if (s.joined) {
      s.mapper.reset();  // not in use: only the step-runner steps it, and it is here
    } else if (s.mapper == nullptr && !s.early.empty()) {
      PLX_ASSIGN_OR_RETURN(s.mapper, SlamMapper::Create(mapper_options_, backend_));
      for (const EarlyKeyframe& k : s.early) {
        PLX_RETURN_IF_ERROR(s.mapper->AddKeyframe(k.frame, k.pose, k.intrinsics));
      }
      s.early.clear();
    }
  }
  // Integration before iterations: a camera tracking in a segment carries on odometry until
  // its keyframes are in, while the main map's iteration budget may last seconds.
  const bool drain = mode == SlamStepMode::kDrain;
  for (const bool integrating : {true, false}) {
    if (drain && !integrating) break;
    for (size_t i = 0; i < count; ++i) {
      Segment& s = *segments_[i];
      if (s.joined || s.mapper == nullptr) continue;
      if (integrating ? s.progress.pending_keyframes > 0 : s.has_work) {
        *main = i == 0;
        return &s;
      }
    }
  }
  *main = true;
  return segments_[0].get();  // out of work: the main map publishes what is left
}

absl::StatusOr<SlamStepResult> SlamCoordinator::Step(SlamStepMode mode) {
  bool main = true;
  PLX_ASSIGN_OR_RETURN(Segment * segment, SegmentToStep(mode, &main));
  bool rebuilding = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    Segment& m = *segments_[0];
    if (m.rebuild != nullptr && mode == SlamStepMode::kDrain) {
      // Draining (the daemon's shutdown) saves what was accepted, soon: a rebuild would take
      // as long as mapping everything again. The map is saved uncorrected.
      m.rebuild.reset();
      m.rebuild_solve.reset();
      ++loop_counts_.rebuilds_abandoned;
    }
    rebuilding = m.rebuild != nullptr;
  }
  if (rebuilding && main) {
    // The main map and the rebuild in turn; the rebuild alone once the main one is idle, or
    // when finishing: no camera tracks against the main map any more, and the rebuild has every
    // keyframe and replaces it, so its remaining iterations would be thrown away.
    Segment& m = *segments_[0];
    m.step_rebuild_next = !m.step_rebuild_next;
    if (m.step_rebuild_next || !m.mapper->has_work() || mode == SlamStepMode::kFinish) {
      return StepRebuild();
    }
  }
  PLX_ASSIGN_OR_RETURN(SlamStepResult out, StepSegment(segment, main, mode));
  if (main) PLX_RETURN_IF_ERROR(CloseLoops(mode));
  // Out of work only once every map is (SegmentToStep chose the main map last), and no
  // rebuild or correction is under way.
  if (!main) out.out_of_work = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (segments_[0]->rebuild != nullptr || segments_[0]->correction_due) {
      out.out_of_work = false;
      segments_[0]->progress.idle = false;
    }
  }
  return out;
}

absl::Status SlamCoordinator::CloseLoops(SlamStepMode mode) {
  Segment& main = *segments_[0];
  const LoopClosureOptions& options = mapper_options_.loop_closure;
  SlamMapper* mapper = nullptr;
  std::vector<std::shared_ptr<const FrameFeatures>> features;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!options.enabled || main.rebuild != nullptr || main.mapper == nullptr) {
      return absl::OkStatus();
    }
    mapper = main.mapper.get();
    features = main.features;
  }
  const TrainingSet& set = mapper->integrated_keyframes();  // ours: we are the step-runner
  const std::vector<SE3> poses = mapper->all_keyframe_poses();
  const int integrated = std::min<int>(set.num_frames(), static_cast<int>(features.size()));
  if (integrated > main.loop_checked) {
    std::vector<LoopKeyframe> keyframes(integrated);
    std::vector<double> timestamps(integrated);
    for (int i = 0; i < integrated; ++i) {
      keyframes[i] = {features[i].get(), &set.frame(i), &set.intrinsics(i), poses[i]};
      timestamps[i] = set.frame(i).timestamp;
    }
    SlamLoopCounts found;
    for (int q = main.loop_checked; q < integrated; ++q) {
      // The sequential edge into q measured from the two keyframes' images: the solve takes it
      // where tracking's relative pose slipped (LoopClosureGraph).
      int from = -1;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (q < static_cast<int>(main.links.size())) {
          from = main.links[q].from >= 0 ? main.links[q].from : q - 1;
        }
      }
      if (from >= 0) {
        PLX_ASSIGN_OR_RETURN(std::optional<SE3> measured,
                             MeasureSequentialLink(keyframes[from], keyframes[q], options));
        found.links_measured += measured.has_value();
        std::lock_guard<std::mutex> lock(mutex_);
        main.links[q].measured = std::move(measured);
      }
      PLX_ASSIGN_OR_RETURN(const LoopSearch search, SearchLoop(q, keyframes, timestamps, options));
      ++found.checked;
      found.proposed += search.proposed;
      found.rejected += search.rejected;
      if (search.loop) {
        ++found.verified;
        std::lock_guard<std::mutex> lock(mutex_);
        main.loops.push_back(*search.loop);
        main.correction_due = true;
      }
    }
    main.loop_checked = integrated;
    std::lock_guard<std::mutex> lock(mutex_);
    loop_counts_.checked += found.checked;
    loop_counts_.proposed += found.proposed;
    loop_counts_.rejected += found.rejected;
    loop_counts_.verified += found.verified;
    loop_counts_.links_measured += found.links_measured;
  }
  // A rebuild costs about as much as mapping its keyframes again: one that would start soon
  // after the last waits for min_keyframes_between_rebuilds more (or the end of the run), the
  // loops found meanwhile kept for its solve.
  const bool soon = main.rebuilt_at >= 0 &&
                    integrated - main.rebuilt_at < options.min_keyframes_between_rebuilds;
  if (main.correction_due && soon && mode == SlamStepMode::kMap) {
    main.correction_due = false;
    main.correction_deferred = true;
  } else if (main.correction_deferred && (!soon || mode == SlamStepMode::kFinish)) {
    main.correction_deferred = false;
    main.correction_due = true;
  }
  // The solve needs every accepted keyframe integrated: the rebuild takes them from the
  // mapper's own keyframes.
  if (!main.correction_due || mapper->progress().pending_keyframes > 0) return absl::OkStatus();
  return CorrectAndRebuild(mapper);
}

absl::Status SlamCoordinator::CorrectAndRebuild(SlamMapper* mapper) {
  Segment& main = *segments_[0];
  const LoopClosureOptions& options = mapper_options_.loop_closure;
  const std::vector<SE3> poses = mapper->all_keyframe_poses();
  std::vector<LoopEdge> loops;
  std::vector<SequentialLink> links;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    loops = main.loops;
    links = main.links;
  }
  PLX_ASSIGN_OR_RETURN(const LoopCorrection correction,
                       CorrectKeyframes(poses, loops, options, links));
  main.correction_due = false;
  std::vector<LoopEdge> kept;
  for (size_t i = 0; i < loops.size(); ++i) {
    if (std::find(correction.rejected_loops.begin(), correction.rejected_loops.end(),
                  static_cast<int>(i)) == correction.rejected_loops.end()) {
      kept.push_back(loops[i]);
    }
  }
  auto solve = std::make_shared<SlamCorrection>();
  solve->before = poses;
  solve->after = correction.poses;
  solve->max_shift_m = correction.max_shift_m;
  solve->solve_ms = correction.solve_seconds * 1e3;
  solve->loops = static_cast<int>(kept.size());
  // How far each keyframe's surface moves: a correction within in_place_max_shift_m is
  // applied in the running map, as refinement applies its own, instead of rebuilding it.
  const TrainingSet& set = mapper->integrated_keyframes();
  KeyframeMoves moves;
  if (correction.significant && set.num_frames() == static_cast<int>(poses.size())) {
    PLX_ASSIGN_OR_RETURN(moves, MeasureKeyframeMoves(set, poses, correction.poses,
                                                     mapper_options_.mapping.mapper.voxel_size,
                                                     mapper_options_.mapping.mapper.allocation
                                                         .max_depth,
                                                     mapper_options_.rebuild_seed));
  }
  const bool in_place = moves.largest_m <= mapper_options_.in_place_max_shift_m;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    loop_counts_.rejected += static_cast<int>(correction.rejected_loops.size());
    loop_counts_.accepted = static_cast<int>(kept.size());
    loop_counts_.last_solve_ms = solve->solve_ms;
    loop_counts_.last_shift_m = correction.max_shift_m;
    loop_counts_.last_measured_edges = correction.measured_edges;
    // A keyframe accepted since the poses were read is not in the mapper's keyframes yet
    // (nor in the solve): the next step solves again.
    if (mapper->progress().keyframes != static_cast<int>(poses.size())) {
      main.correction_due = true;
      main.loops = std::move(kept);
      return absl::OkStatus();
    }
    main.loops = std::move(kept);
    if (!correction.significant) return absl::OkStatus();
    if (!in_place) {
      main.rebuild_collecting = true;
      main.rebuild_solve = solve;
      main.rebuilt_at = static_cast<int>(poses.size());
      loop_counts_.rebuilding = true;
    }
  }
  if (in_place) return CorrectInPlace(mapper, *solve, moves.moved_keyframes);
  // Filled outside the lock (copies of every keyframe's images): cameras go on meanwhile and
  // their keyframes wait in the backlog.
  absl::StatusOr<RebuildSeed> seed = SeedFor(mapper, poses, moves);
  absl::StatusOr<std::unique_ptr<SlamMapper>> rebuild =
      seed.ok() ? SlamMapper::Create(mapper_options_, backend_,
                                     seed->map != nullptr ? seed->map : base_)
                : absl::StatusOr<std::unique_ptr<SlamMapper>>(seed.status());
  for (int i = 0; rebuild.ok() && i < set.num_frames(); ++i) {
    const bool earns = seed->moved.empty() || seed->moved[i] != 0;
    absl::Status added = (*rebuild)->AddKeyframe(set.frame(i), correction.poses[i],
                                                 set.intrinsics(i), earns);
    if (!added.ok()) rebuild = added;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  main.rebuild_collecting = false;
  if (seed.ok()) {
    main.rebuild_moved = seed->moved;
    loop_counts_.last_moved_keyframes =
        seed->moved.empty() ? set.num_frames() : seed->moved_keyframes;
    loop_counts_.last_kept_bricks = seed->kept_bricks;
    loop_counts_.last_dropped_bricks = seed->dropped_bricks;
  }
  absl::Status status = rebuild.status();
  for (const EarlyKeyframe& k : main.rebuild_backlog) {
    if (!status.ok()) break;
    status = (*rebuild)->AddKeyframe(k.frame, solve->Move(k.pose), k.intrinsics);
  }
  main.rebuild_backlog.clear();
  if (!status.ok()) {
    main.rebuild_solve.reset();
    loop_counts_.rebuilding = false;
    return status;
  }
  main.rebuild = *std::move(rebuild);
  main.rebuild_refined = false;
  return absl::OkStatus();
}

absl::Status SlamCoordinator::CorrectInPlace(SlamMapper* mapper, const SlamCorrection& solve,
                                             int moved) {
  Segment& main = *segments_[0];
  const double extra = mapper_options_.rebuild_iteration_share *
                       mapper_options_.mapping.iterations_per_keyframe * moved;
  PLX_RETURN_IF_ERROR(mapper->MoveKeyframes(solve.after, static_cast<int>(std::lround(extra))));
  // Published now, so the correction reaches cameras with the version it belongs to; the
  // granted iterations fit the map to the moved keyframes in the versions after it.
  PLX_RETURN_IF_ERROR(mapper->PublishIfChanged());
  const SlamMapVersion latest = mapper->latest();
  SetPublishedKeyframes(*mapper);
  int64_t number = latest.version + main.version_offset;
  if (publisher_) {
    PLX_ASSIGN_OR_RETURN(number, publisher_(latest.map, 0));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  auto correction = std::make_shared<SlamCorrection>(solve);
  correction->map_version = number;
  correction->after = mapper->all_keyframe_poses();
  RecordCorrectionLocked(main, std::move(correction));
  AdoptCorrectedVersionLocked(main, *mapper, latest, number);
  ++loop_counts_.corrections;
  ++loop_counts_.in_place;
  return absl::OkStatus();
}

void SlamCoordinator::AdoptCorrectedVersionLocked(Segment& main, const SlamMapper& mapper,
                                                  const SlamMapVersion& latest,
                                                  int64_t number) {
  main.published = {latest.map, number};
  main.version_offset = number - latest.version;
  main.handed_mapper_version = latest.version;
  const SlamMapperProgress p = mapper.progress();
  main.integrated_at_publish = p.keyframes_integrated;
  main.has_work = mapper.has_work();
  const int keyframes = main.progress.keyframes;
  main.progress = p;
  main.progress.keyframes = keyframes;
  main.progress.pending_keyframes = keyframes - p.keyframes_integrated;
  main.progress.map_version = number;
  main.progress.idle = IdleLocked(main);
}

absl::StatusOr<RebuildSeed> SlamCoordinator::SeedFor(SlamMapper* mapper,
                                                     const std::vector<SE3>& before,
                                                     const KeyframeMoves& moves) {
  if (!mapper_options_.rebuild_keeps_unmoved) {
    RebuildSeed none;  // from the base map, every keyframe earning
    none.dropped_bricks = mapper->latest().map != nullptr
                              ? mapper->latest().map->grid.num_bricks() : 0;
    return none;
  }
  // The seed is the old map as it is now: every integrated keyframe's bricks are in it.
  PLX_RETURN_IF_ERROR(mapper->PublishIfChanged());
  const std::shared_ptr<const PlenoxelMap> old = mapper->latest().map;
  if (old == nullptr) return RebuildSeed{};
  return SeedRebuild(*old, mapper->integrated_keyframes(), before, moves,
                     mapper_options_.mapping.mapper.allocation, *backend_);
}

absl::StatusOr<SlamStepResult> SlamCoordinator::StepRebuild() {
  Segment& main = *segments_[0];
  SlamMapper* rebuild = nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    rebuild = main.rebuild.get();
  }
  SlamStepResult out;
  if (rebuild->has_work()) {
    PLX_RETURN_IF_ERROR(rebuild->Step(/*finish=*/false).status());
    out.stepped = true;
  }
  const SlamMapperProgress p = rebuild->progress();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    loop_counts_.rebuild_iterations = p.mapping_iterations;
    loop_counts_.rebuild_iteration_budget = p.iteration_budget;
  }
  const double budget = p.iteration_budget;
  // Ready once every keyframe is in and it has had its share of the iterations (the rest
  // after the swap); finishing steps it until then too.
  const bool trained = !rebuild->has_work() ||
                       p.mapping_iterations >= mapper_options_.rebuild_iteration_share * budget;
  if (p.pending_keyframes == 0 && trained) {
    if (mapper_options_.rebuild_refines_all && !main.rebuild_refined) {
      // One bounded step of its own: the swap is the next one, with the refined poses.
      // The keyframes the solve moved, and those that reached the rebuild after it (moved by
      // it too); every one for a rebuild from nothing.
      std::vector<uint8_t> refine = main.rebuild_moved;
      if (!refine.empty()) refine.resize(static_cast<size_t>(p.keyframes_integrated), 1);
      PLX_RETURN_IF_ERROR(rebuild->RefineAllKeyframes(refine).status());
      main.rebuild_refined = true;
      out.stepped = true;
      return out;
    }
    return SwapInRebuild();
  }
  return out;
}

absl::StatusOr<SlamStepResult> SlamCoordinator::SwapInRebuild() {
  Segment& main = *segments_[0];
  SlamMapper* rebuild = nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    rebuild = main.rebuild.get();
  }
  PLX_RETURN_IF_ERROR(rebuild->PublishIfChanged());
  const SlamMapVersion latest = rebuild->latest();
  SetPublishedKeyframes(*rebuild);
  int64_t number = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    number = main.published.version + 1;
  }
  if (publisher_) {
    PLX_ASSIGN_OR_RETURN(number, publisher_(latest.map, 0));
  }
  SlamStepResult out;
  out.stepped = true;
  out.published = true;
  std::unique_ptr<SlamMapper> old;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto correction = std::make_shared<SlamCorrection>(*main.rebuild_solve);
    correction->map_version = number;
    // Exactly how every keyframe moved between the frames: each mapper has every keyframe
    // (both were given each one), the old one refined as mapping went on meanwhile.
    correction->before = main.mapper->all_keyframe_poses();
    correction->after = rebuild->all_keyframe_poses();
    RecordCorrectionLocked(main, std::move(correction));
    old = std::move(main.mapper);
    main.mapper = std::move(main.rebuild);
    main.rebuild_solve.reset();
    AdoptCorrectedVersionLocked(main, *main.mapper, latest, number);
    ++loop_counts_.corrections;
    loop_counts_.rebuilding = false;
  }
  out.out_of_work = !main.mapper->has_work();
  return out;  // `old` goes here, outside the lock
}

absl::StatusOr<SlamStepResult> SlamCoordinator::StepSegment(Segment* segment, bool main,
                                                            SlamStepMode mode) {
  SlamMapper* mapper = nullptr;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    mapper = segment->mapper.get();
  }
  if (mapper == nullptr) return absl::FailedPreconditionError("StartMapper before Step");
  SlamStepResult out;
  const bool drain = mode == SlamStepMode::kDrain;
  // Draining: only the keyframes already accepted are integrated; the rest of the iteration
  // budget is not spent, so the map is saved soon.
  const bool work = drain ? mapper->progress().pending_keyframes > 0 : mapper->has_work();
  if (work) {
    PLX_RETURN_IF_ERROR(mapper->Step(/*finish=*/mode != SlamStepMode::kMap).status());
    out.stepped = true;
  }
  out.out_of_work =
      !mapper->has_work() || (drain && mapper->progress().pending_keyframes == 0);
  // A segment's keyframe is in but not in a version: SegmentToStep gives the main map's
  // iterations the turn until the main map runs out of work (minutes on a busy map), so the
  // segment would not be stepped, nor published, before then. Its camera needs the version:
  // the first one to track at all (a realtime replay hung waiting for it), the later ones to
  // track where its new keyframes reach. The fused keyframes are a map to track against;
  // publish them now.
  const bool unpublished_keyframes =
      !main && mapper->progress().keyframes_integrated > segment->integrated_at_publish;
  // Out of work: what the last iterations changed is published now, not at the next keyframe
  // (a lock-step camera waits for exactly this).
  if (out.out_of_work || unpublished_keyframes) {
    PLX_RETURN_IF_ERROR(mapper->PublishIfChanged());
  }

  // Every new version of the main map gets the map's number (the publisher's, else the
  // mapper's own); a segment's versions keep the mapper's.
  const SlamMapVersion latest = mapper->latest();
  const int integrated = mapper->progress().keyframes_integrated;
  int64_t number = latest.version + segment->version_offset;
  if (latest.map != nullptr && latest.version != segment->handed_mapper_version) {
    if (main) SetPublishedKeyframes(*mapper);
    if (publisher_ && main) {
      PLX_ASSIGN_OR_RETURN(
          number, publisher_(latest.map, integrated - segment->integrated_at_publish));
    }
    segment->handed_mapper_version = latest.version;
    segment->integrated_at_publish = integrated;
    out.published = true;
  }

  std::lock_guard<std::mutex> lock(mutex_);
  if (out.published) segment->published = {latest.map, number};
  segment->has_work = mapper->has_work();
  const int keyframes = segment->progress.keyframes;
  segment->progress = mapper->progress();
  segment->progress.keyframes = keyframes;  // the same once `early` is handed over
  segment->progress.pending_keyframes = keyframes - segment->progress.keyframes_integrated;
  segment->progress.map_version = segment->published.version;
  segment->progress.idle = IdleLocked(*segment);
  return out;
}

bool SlamCoordinator::IdleLocked(const Segment& segment) const {
  return segment.mapper != nullptr && !segment.has_work && segment.early.empty() &&
         segment.progress.pending_keyframes == 0 && segment.rebuild == nullptr &&
         !segment.correction_due;
}

int SlamCoordinator::CurrentGenerationLocked() const {
  const Segment& main = *segments_[0];
  const std::shared_ptr<const SlamCorrection> latest = main.correction();
  return latest != nullptr ? latest->generation : 0;
}

std::vector<SequentialLink> SlamCoordinator::sequential_links() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return segments_[0]->links;
}

std::vector<LoopEdge> SlamCoordinator::loops() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<LoopEdge> loops = segments_[0]->loops;
  // The graph numbers the mapper's keyframes; the main map's list starts with the saved ones.
  const int saved = static_cast<int>(saved_.size());
  for (LoopEdge& loop : loops) {
    loop.from += saved;
    loop.to += saved;
  }
  return loops;
}

std::shared_ptr<const SlamCorrection> SlamCoordinator::correction() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return segments_[0]->correction();
}

std::vector<std::shared_ptr<const SlamCorrection>> SlamCoordinator::CorrectionsAfter(
    int generation) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::deque<std::shared_ptr<const SlamCorrection>>& kept = segments_[0]->corrections;
  if (kept.empty() || kept.front()->generation > generation + 1) return {};
  std::vector<std::shared_ptr<const SlamCorrection>> after;
  for (const std::shared_ptr<const SlamCorrection>& c : kept) {
    if (c->generation > generation) after.push_back(c);
  }
  return after;
}

void SlamCoordinator::RecordCorrectionLocked(Segment& main,
                                             std::shared_ptr<SlamCorrection> correction) {
  correction->generation = CurrentGenerationLocked() + 1;
  main.corrections.push_back(std::move(correction));
  if (main.corrections.size() > static_cast<size_t>(kKeptCorrections)) {
    main.corrections.pop_front();
  }
}

SlamMapView SlamCoordinator::ViewLocked(int segment) const {
  SlamMapView view;
  const Segment& s = *segments_[segment];
  view.segment = segment;
  view.map = s.published.map;
  view.version = s.published.map != nullptr ? s.published.version : 0;
  if (s.mapper == nullptr) {
    for (const EarlyKeyframe& k : s.early) {
      view.accepted_keyframes.push_back({k.frame.timestamp, k.pose});
    }
  } else {
    view.accepted_keyframes = s.mapper->accepted_keyframes();
    view.keyframe_poses = s.mapper->keyframe_poses();
    view.keyframe_features = s.features;
  }
  if (segment == 0) {
    // The saved keyframes first: relocalisation and the keyframe policy see the whole map.
    // Poses and features stay index-aligned (both lists start with the same saved ones).
    view.accepted_keyframes = AfterSaved(saved_poses_, std::move(view.accepted_keyframes));
    view.keyframe_poses = AfterSaved(saved_poses_, std::move(view.keyframe_poses));
    view.keyframe_features =
        AfterSaved(saved_features_, s.mapper == nullptr ? decltype(view.keyframe_features){}
                                                        : std::move(view.keyframe_features));
  }
  view.pending_keyframes = s.progress.pending_keyframes;
  view.map_rebuilding = s.rebuild != nullptr || s.rebuild_collecting;
  if (segment == 0) view.correction = s.correction();
  return view;
}

SlamMapView SlamCoordinator::View(int segment) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (segment <= 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    return ViewLocked(0);
  }
  SlamMapView view = ViewLocked(segment);
  view.main = std::make_shared<const SlamMapView>(ViewLocked(0));
  return view;
}

bool SlamCoordinator::MayCameraProceed(int segment, bool needs_version) const {
  return MayCameraProceed(gate_.max_pending_keyframes, segment, needs_version);
}

bool SlamCoordinator::MayCameraProceed(int max_pending_keyframes, int segment,
                                       bool needs_version) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (segment < 0 || segment >= static_cast<int>(segments_.size()) ||
      segments_[segment]->joined) {
    segment = 0;
  }
  const Segment& s = *segments_[segment];
  if (s.progress.pending_keyframes > max_pending_keyframes) return false;
  if (needs_version && s.published.map == nullptr) return false;
  return !gate_.lock_step || IdleLocked(s);
}

SlamMapperProgress SlamCoordinator::progress() const {
  std::lock_guard<std::mutex> lock(mutex_);
  SlamMapperProgress progress = segments_[0]->progress;
  progress.loops = loop_counts_;
  // The saved keyframes are in the base map: accepted and integrated long ago.
  progress.keyframes += static_cast<int>(saved_.size());
  progress.keyframes_integrated += static_cast<int>(saved_.size());
  return progress;
}

SlamMapVersion SlamCoordinator::latest() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return segments_[0]->published;
}

std::vector<StampedPose> SlamCoordinator::keyframe_poses() const {
  std::lock_guard<std::mutex> lock(mutex_);
  const Segment& main = *segments_[0];
  return AfterSaved(saved_poses_, main.mapper == nullptr ? std::vector<StampedPose>{}
                                                         : main.mapper->keyframe_poses());
}

SlamSegmentCounts SlamCoordinator::segments() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return segment_counts_;
}

}  // namespace plx
