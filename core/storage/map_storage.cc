#include "core/storage/map_storage.h"

#include <optional>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

// Races are between a few daemons that each renew a few times a lease term; a swap lost this
// many times in a row means the storage is not behaving.
constexpr int kSwapAttempts = 5;

// What a decision makes of a lease record: the record to store instead, nullopt to leave it
// as it is, or a refusal (returned as is).
using LeaseChoice = absl::StatusOr<std::optional<LeaseRecord>>;
using LeaseDecision = std::function<LeaseChoice(const LeaseRecord& current)>;

// Reads `name`'s lease record and stores what `decide` makes of it by compare-and-swap; a
// race lost to another writer is decided again on the record it wrote. Returns the record
// stored (or left); `during` names the operation when the races never end.
absl::StatusOr<LeaseRecord> SwapDecided(MapStorage& storage, const std::string& name,
                                        const char* during, const LeaseDecision& decide) {
  for (int attempt = 0; attempt < kSwapAttempts; ++attempt) {
    absl::StatusOr<LeaseRecord> current = storage.ReadLease(name);
    if (!current.ok()) return current.status();
    LeaseChoice next = decide(*current);
    if (!next.ok()) return next.status();
    if (!next->has_value()) return *current;
    absl::StatusOr<LeaseRecord> stored = storage.SwapLease(name, current->revision, **next);
    if (!absl::IsAborted(stored.status())) return stored;
  }
  return absl::UnavailableError(absl::StrCat("map \"", name, "\": its lease record changed ",
                                             kSwapAttempts, " times while ", during, " (",
                                             storage.Describe(), ")"));
}

}  // namespace

absl::StatusOr<LeaseRecord> AcquireLease(MapStorage& storage, const std::string& name,
                                         const std::string& holder, uint64_t held_token,
                                         const std::function<absl::Time()>& clock,
                                         const LeaseTerms& terms) {
  return SwapDecided(storage, name, "it was being taken",
                     [&](const LeaseRecord& current) -> LeaseChoice {
                       return NextLease(name, current, holder, held_token, clock(), terms);
                     });
}

absl::StatusOr<LeaseRecord> RecordHandoffRequest(MapStorage& storage, const std::string& name,
                                                 const std::string& requester,
                                                 const std::function<absl::Time()>& clock,
                                                 const LeaseTerms& terms) {
  return SwapDecided(storage, name, "a handoff was asked",
                     [&](const LeaseRecord& current) -> LeaseChoice {
                       return RequestHandoff(name, current, requester, clock(), terms);
                     });
}

absl::StatusOr<LeaseRecord> TakeOrRequestLease(MapStorage& storage, const std::string& name,
                                               const std::string& holder,
                                               const std::function<absl::Time()>& clock,
                                               const LeaseTerms& terms, bool* handed_over) {
  for (int attempt = 0; attempt < kSwapAttempts; ++attempt) {
    LeaseRecord seen;  // the record the take was decided on
    absl::Time now;
    absl::StatusOr<LeaseRecord> taken = SwapDecided(
        storage, name, "it was being taken",
        [&](const LeaseRecord& current) -> LeaseChoice {
          seen = current;
          now = clock();
          return NextLease(name, current, holder, 0, now, terms);
        });
    if (taken.ok()) {
      if (handed_over != nullptr) {
        // Released (not expired) while our request stood: the holder gave it to us.
        *handed_over = seen.wanted_by == holder && seen.wanted_until > now &&
                       seen.expires == ReleasedLease(seen).expires;
      }
      return taken;
    }
    // Held by another: ask for it (reserved for another: say where it is going).
    if (!absl::IsFailedPrecondition(taken.status())) return taken.status();
    absl::StatusOr<LeaseRecord> asked = RecordHandoffRequest(storage, name, holder, clock, terms);
    if (asked.ok()) return HandoffRequestedError(name, *asked, terms);
    // Freed meanwhile: take it on the next round.
    if (!absl::IsFailedPrecondition(asked.status())) return asked.status();
  }
  return absl::UnavailableError(absl::StrCat("map \"", name, "\": it was freed and taken again ",
                                             kSwapAttempts, " times while it was being taken (",
                                             storage.Describe(), ")"));
}

absl::Status ReleaseLease(MapStorage& storage, const std::string& name,
                          const std::string& holder, uint64_t token) {
  return SwapDecided(storage, name, "it was released",
                     [&](const LeaseRecord& current) -> LeaseChoice {
                       // Not ours (any more): nothing to give up.
                       if (current.holder != holder || current.token != token) {
                         return std::nullopt;
                       }
                       return ReleasedLease(current);
                     })
      .status();
}

}  // namespace plx
