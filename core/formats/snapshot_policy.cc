#include "core/formats/snapshot_policy.h"

#include <algorithm>

namespace plx {

void MapSaveState::MarkClean(uint64_t version) {
  version_ = version;
  saved_version_ = version;
  dirty_ = false;
  unsaved_since_ = absl::InfiniteFuture();
  changed_while_saving_ = absl::InfiniteFuture();
  not_before_ = absl::InfinitePast();
}

void MapSaveState::Changed(uint64_t version, absl::Time now) {
  version_ = version;
  if (!dirty_) {
    dirty_ = true;
    unsaved_since_ = now;
  }
  if (saving_ && changed_while_saving_ == absl::InfiniteFuture()) changed_while_saving_ = now;
}

void MapSaveState::SaveStarted(uint64_t version, absl::Time now) {
  save_started_ = now;
  saving_ = true;
  saving_version_ = version;
  changed_while_saving_ = absl::InfiniteFuture();
}

void MapSaveState::SaveFinished(bool ok, absl::Time now, absl::Duration retry_after) {
  saving_ = false;
  if (!ok) {
    not_before_ = now + retry_after;
    return;
  }
  not_before_ = absl::InfinitePast();
  last_save_took_ = std::max(absl::ZeroDuration(), now - save_started_);
  saved_version_ = saving_version_;
  if (version_ == saving_version_) {
    dirty_ = false;
    unsaved_since_ = absl::InfiniteFuture();
  } else {
    // What changed while the file was written is the oldest change not in it.
    unsaved_since_ = changed_while_saving_;
  }
  changed_while_saving_ = absl::InfiniteFuture();
}

absl::Time MapSaveState::NextSnapshotDue(absl::Duration interval) const {
  if (interval <= absl::ZeroDuration() || !dirty_ || saving_) return absl::InfiniteFuture();
  // Started early by what the last save took, so it ends about `interval` after the change.
  const absl::Duration lead = std::min(last_save_took_, interval);
  return std::max(unsaved_since_ + interval - lead, not_before_);
}

bool MapSaveState::SnapshotDue(absl::Duration interval, absl::Time now) const {
  return now >= NextSnapshotDue(interval);
}

}  // namespace plx
