// When a map with unsaved changes is saved in the background (a snapshot): the rule that bounds
// what a crash can lose, kept apart from the threads and files that carry it out (the daemon:
// server/snapshot_scheduler.h), so any program holding maps applies the same one.
//
// The rule: a map is due once its oldest change that is not on disk is `interval` old, less
// the time its last save took (so the file holds that change by the time `interval` has passed,
// if this save takes as long), unless one of its saves is running (never two at once) or a
// failed save asked to wait. So a crash loses at most about `interval` of changes, however
// often the map changes (more only when saves take longer than the one before, or than the
// interval itself); a map that stops changing is saved once and then not again.
//
// A save writes the version published when it starts (a copy-on-write version nobody writes),
// so changes made while it runs are not in it: they count as unsaved from the moment the
// first of them was made.
#pragma once

#include <cstdint>

#include "absl/time/time.h"

namespace plx {

// The daemon's default (plenoxd --snapshot-seconds; docs/LIMITS.md says why 30 s).
inline constexpr double kDefaultSnapshotSeconds = 30.0;

// One map's unsaved changes and saves (MapStore keeps one per map). Not thread-safe: its owner
// guards it.
class MapSaveState {
 public:
  // Everything up to `version` is on disk (a map just loaded from its file), or there is
  // nothing worth saving (a map just created, empty).
  void MarkClean(uint64_t version);
  // A new version was published at `now`.
  void Changed(uint64_t version, absl::Time now);
  // A save of `version` (the newest, taken when the save starts) began at `now`.
  void SaveStarted(uint64_t version, absl::Time now);
  // The save ended. A failed one leaves the changes unsaved and the map not due again before
  // `now + retry_after` (a full disk is not hammered every second).
  void SaveFinished(bool ok, absl::Time now, absl::Duration retry_after = absl::ZeroDuration());

  bool dirty() const { return dirty_; }
  bool saving() const { return saving_; }
  uint64_t version() const { return version_; }
  uint64_t saved_version() const { return saved_version_; }
  // When the oldest unsaved change was made (InfiniteFuture when clean).
  absl::Time unsaved_since() const { return unsaved_since_; }

  // Whether a snapshot is due at `now` (`interval` zero or negative: snapshots are off).
  bool SnapshotDue(absl::Duration interval, absl::Time now) const;
  // When one will be due if nothing else happens (InfiniteFuture: not while the map is clean,
  // saving, or snapshots are off).
  absl::Time NextSnapshotDue(absl::Duration interval) const;

 private:
  uint64_t version_ = 0;
  uint64_t saved_version_ = 0;
  bool dirty_ = false;
  absl::Time unsaved_since_ = absl::InfiniteFuture();
  bool saving_ = false;
  uint64_t saving_version_ = 0;
  // The first change made while a save runs: the oldest one that save does not hold.
  absl::Time changed_while_saving_ = absl::InfiniteFuture();
  absl::Time save_started_ = absl::InfinitePast();
  absl::Duration last_save_took_ = absl::ZeroDuration();  // the last successful save
  absl::Time not_before_ = absl::InfinitePast();
};

}  // namespace plx
