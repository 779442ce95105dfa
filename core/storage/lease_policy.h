// Who may write a map kept in shared storage (plenoxd --shared-dir): the lease rule, kept apart
// from the storage that stores leases (core/storage/map_storage.h) and the daemon that renews
// them (server/lease_keeper.h), so it is tested with a fake clock and any program holding
// shared maps applies the same one.
//
// The rule. Each map has one lease record: a holder (a daemon's id, MakeHolderId), an expiry,
// and a fencing token, a generation number raised by one every time the lease changes hands
// and never lowered (a released lease keeps its token, so the next holder's is higher still).
//   - Taking: a lease nobody holds (never held, released, or expired) is taken with the next
//     token. A lease another holder holds unexpired is refused, naming that holder.
//   - Keeping: the holder renews its lease under the token it holds (same token, new expiry),
//     also after its expiry as long as nobody took the lease meanwhile (then nobody can have
//     written the map either). Once the record names another token, the old holder has lost
//     the map for good: its copy may be older than what the new owner wrote, so it drops it
//     (LeaseLost) and may only take the lease again, with a new token, and reload the file.
//   - Writing: a holder writes a map only while the record still names it with its token and
//     at least `write_margin` of the lease is left by its own clock (CheckFence). The storage
//     runs that check atomically with publishing the file (under a lock, or as a conditional
//     write), so a holder that was paused past its expiry and resumes writes nothing: the
//     record it finds names the new owner's higher token.
//
// Handoff (a map moving to the daemon its router now sends it to: a replica was added, or the
// router's view changed). A daemon asked for a map whose lease another holds live records a
// request in the lease record (RequestHandoff: its id and an expiry, `handoff_wait` from
// now, refreshed by every call it gets for the map) and answers UNAVAILABLE, which clients
// retry. The holder sees the request at its next renewal and gives the map up (a fenced save,
// then the copy dropped and the lease released) only when
//   - no mapping job (Integrate stream, Slam job) holds the map, and
//   - no call naming the map has reached it for `handoff_quiet`.
// A released lease whose request is still pending is reserved for the requester until the
// request expires: another daemon's take is refused, so the map cannot bounce back to the
// old holder or sideways. Against ping-pong: a map moves only away from a holder its clients
// stopped calling; when two routers disagree, both daemons keep getting calls, the holder
// keeps the map, and the other's callers wait (UNAVAILABLE) until the routers agree or
// their retries run out. A request whose requester died lapses after `handoff_wait`.
//
// Expiries are wall-clock times compared across machines: clocks must agree to well within
// `write_margin` (NTP does; docs/ARCHITECTURE.md, "Shared map storage").
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/time/time.h"

namespace plx {

// The daemon's default lease (plenoxd --lease-seconds): a dead owner's maps move after at most
// this long; renewals every third of it leave two chances to miss one.
inline constexpr double kDefaultLeaseSeconds = 15.0;

struct LeaseRecord {
  std::string holder;                         // empty: never held
  uint64_t token = 0;                         // the fencing token; 0: never held
  absl::Time expires = absl::InfinitePast();  // free from then on
  // The storage's version of the record, for compare-and-swap (MapStorage::SwapLease); set by
  // the storage when it reads or writes the record, 0 when there is none.
  uint64_t revision = 0;
  // A pending handoff request (RequestHandoff): the daemon that wants the map, and until when
  // the request (or, once the lease is released, the reservation) stands. Empty: none.
  std::string wanted_by;
  absl::Time wanted_until = absl::InfinitePast();
};

struct LeaseTerms {
  absl::Duration term = absl::Seconds(kDefaultLeaseSeconds);  // how long a take or renewal lasts
  absl::Duration renew_every = absl::Seconds(kDefaultLeaseSeconds / 3);
  // A holder stops writing this long before its lease expires by its own clock: the time a
  // commit takes after its check, and clock skew between the daemons.
  absl::Duration write_margin = absl::Seconds(kDefaultLeaseSeconds / 4);
  // Handoff: a holder gives a wanted map up only after this long without a call naming it, and
  // a request (and the reservation of a lease released for it) lasts this long.
  absl::Duration handoff_quiet = absl::Seconds(kDefaultLeaseSeconds / 3);
  absl::Duration handoff_wait = absl::Seconds(kDefaultLeaseSeconds);
};

// The terms for a lease of `term`: renewed every third of it, no writes in its last quarter;
// handoffs after a third of it without calls, requests lasting one term.
LeaseTerms LeaseTermsFor(absl::Duration term);

// A holder id: "<host>-<pid>-<random hex>", characters other than [A-Za-z0-9._] of the host
// replaced by '_' and the host cut at 64 characters (ids go into file names and log lines).
// The random part tells a restarted process with a reused pid from the one before it.
std::string MakeHolderId(absl::string_view host, int64_t pid, uint64_t random);

// Whether `lease` is free at `now` (never held, released or expired).
bool LeaseFree(const LeaseRecord& lease, absl::Time now);

// The record that takes or keeps `map`'s lease for `holder` at `now`, given the stored record
// `current`. `held_token`: the token the caller holds the map under (0: it does not hold it).
// A renewal keeps the token (and any handoff request); a take raises it and clears the
// request. FAILED_PRECONDITION when another holder has it (naming it, its generation and the
// seconds left), or, with `held_token` set, when the record names another token: the lease was
// lost (IsLeaseLost). UNAVAILABLE when it is free but reserved for another daemon's pending
// request (the map is moving there).
absl::StatusOr<LeaseRecord> NextLease(absl::string_view map, const LeaseRecord& current,
                                      absl::string_view holder, uint64_t held_token,
                                      absl::Time now, const LeaseTerms& terms);

// Whether `holder` may write `map` under `token` at `now`, the stored record being `current`:
// OK while the record names it with that token and write_margin is left. FAILED_PRECONDITION
// otherwise: lost (IsLeaseLost, naming the new generation) when the record names another
// holder or token; expired (not lost: nobody took it, a renewal may keep it) when too little
// is left.
absl::Status CheckFence(absl::string_view map, const LeaseRecord& current,
                        absl::string_view holder, uint64_t token, absl::Time now,
                        const LeaseTerms& terms);

// `current` given up: free at once, its token kept (the next holder's is higher), a pending
// handoff request kept (the lease stays reserved for it).
LeaseRecord ReleasedLease(const LeaseRecord& current);

// Whether `lease` holds an unexpired handoff request of a daemon other than `holder`.
bool HandoffPending(const LeaseRecord& lease, absl::string_view holder, absl::Time now);

// The record with `requester`'s handoff request (a new one replaces an older one: the latest
// router view wins), to be stored with a compare-and-swap. Only against a live lease of
// another holder: FAILED_PRECONDITION when `requester` holds it or it is free and not
// reserved (take it instead), UNAVAILABLE when it is free and reserved for another.
absl::StatusOr<LeaseRecord> RequestHandoff(absl::string_view map, const LeaseRecord& current,
                                           absl::string_view requester, absl::Time now,
                                           const LeaseTerms& terms);

// What a requester answers its caller once its request is stored: UNAVAILABLE (retry) naming
// the holder, its generation and what it waits for. IsHandoffRequested tells it apart.
absl::Status HandoffRequestedError(absl::string_view map, const LeaseRecord& current,
                                   const LeaseTerms& terms);
bool IsHandoffRequested(const absl::Status& status);

// Whether a holder with a pending request gives the map up now: no mapping job holds it and
// the last call naming it is at least handoff_quiet old.
bool ShouldHandOff(bool mapping, absl::Time last_call, absl::Time now, const LeaseTerms& terms);

// Whether `status` says the caller's lease on a map was taken over (NextLease, CheckFence):
// the caller no longer owns the map and must drop its copy.
bool IsLeaseLost(const absl::Status& status);

}  // namespace plx
