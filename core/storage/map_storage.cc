#include "core/storage/map_storage.h"

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

// Races are between a few daemons that each renew a few times a lease term; a swap lost this
// many times in a row means the storage is not behaving.
constexpr int kSwapAttempts = 5;

}  // namespace

absl::StatusOr<LeaseRecord> AcquireLease(MapStorage& storage, const std::string& name,
                                         const std::string& holder, uint64_t held_token,
                                         const std::function<absl::Time()>& clock,
                                         const LeaseTerms& terms) {
  for (int attempt = 0; attempt < kSwapAttempts; ++attempt) {
    absl::StatusOr<LeaseRecord> current = storage.ReadLease(name);
    if (!current.ok()) return current.status();
    absl::StatusOr<LeaseRecord> next =
        NextLease(name, *current, holder, held_token, clock(), terms);
    if (!next.ok()) return next.status();
    absl::StatusOr<LeaseRecord> stored = storage.SwapLease(name, current->revision, *next);
    if (!absl::IsAborted(stored.status())) return stored;
  }
  return absl::UnavailableError(absl::StrCat("map \"", name, "\": its lease record changed ",
                                             kSwapAttempts, " times while it was being taken (",
                                             storage.Describe(), ")"));
}

absl::StatusOr<LeaseRecord> RecordHandoffRequest(MapStorage& storage, const std::string& name,
                                                 const std::string& requester,
                                                 const std::function<absl::Time()>& clock,
                                                 const LeaseTerms& terms) {
  for (int attempt = 0; attempt < kSwapAttempts; ++attempt) {
    absl::StatusOr<LeaseRecord> current = storage.ReadLease(name);
    if (!current.ok()) return current.status();
    absl::StatusOr<LeaseRecord> next = RequestHandoff(name, *current, requester, clock(), terms);
    if (!next.ok()) return next.status();
    absl::StatusOr<LeaseRecord> stored = storage.SwapLease(name, current->revision, *next);
    if (!absl::IsAborted(stored.status())) return stored;
  }
  return absl::UnavailableError(absl::StrCat("map \"", name, "\": its lease record changed ",
                                             kSwapAttempts, " times while a handoff was asked (",
                                             storage.Describe(), ")"));
}

absl::StatusOr<LeaseRecord> TakeOrRequestLease(MapStorage& storage, const std::string& name,
                                               const std::string& holder,
                                               const std::function<absl::Time()>& clock,
                                               const LeaseTerms& terms, bool* handed_over) {
  for (int attempt = 0; attempt < kSwapAttempts; ++attempt) {
    absl::StatusOr<LeaseRecord> current = storage.ReadLease(name);
    if (!current.ok()) return current.status();
    const absl::Time now = clock();
    absl::StatusOr<LeaseRecord> next = NextLease(name, *current, holder, 0, now, terms);
    if (next.ok()) {
      absl::StatusOr<LeaseRecord> stored = storage.SwapLease(name, current->revision, *next);
      if (absl::IsAborted(stored.status())) continue;
      if (stored.ok() && handed_over != nullptr) {
        // Released (not expired) while our request stood: the holder gave it to us.
        *handed_over = current->wanted_by == holder && current->wanted_until > now &&
                       current->expires == ReleasedLease(*current).expires;
      }
      return stored;
    }
    // Held by another: ask for it (reserved for another: say where it is going).
    if (!absl::IsFailedPrecondition(next.status())) return next.status();
    absl::StatusOr<LeaseRecord> asked = RecordHandoffRequest(storage, name, holder, clock, terms);
    if (asked.ok()) return HandoffRequestedError(name, *asked, terms);
    // Freed meanwhile: take it on the next round.
    if (!absl::IsFailedPrecondition(asked.status())) return asked.status();
  }
  return absl::UnavailableError(absl::StrCat("map \"", name, "\": its lease record changed ",
                                             kSwapAttempts, " times while it was being taken (",
                                             storage.Describe(), ")"));
}

absl::Status ReleaseLease(MapStorage& storage, const std::string& name,
                          const std::string& holder, uint64_t token) {
  for (int attempt = 0; attempt < kSwapAttempts; ++attempt) {
    absl::StatusOr<LeaseRecord> current = storage.ReadLease(name);
    if (!current.ok()) return current.status();
    if (current->holder != holder || current->token != token) return absl::OkStatus();
    absl::StatusOr<LeaseRecord> stored =
        storage.SwapLease(name, current->revision, ReleasedLease(*current));
    if (!absl::IsAborted(stored.status())) return stored.status();
  }
  return absl::UnavailableError(absl::StrCat("map \"", name, "\": its lease record changed ",
                                             kSwapAttempts, " times while it was released (",
                                             storage.Describe(), ")"));
}

}  // namespace plx
