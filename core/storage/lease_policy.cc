#include "core/storage/lease_policy.h"

#include <algorithm>

#include "absl/strings/cord.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace plx {
namespace {

// The payload that marks a lost lease (IsLeaseLost); the code alone cannot, since a lease
// another holder has is FAILED_PRECONDITION too but costs the caller nothing it held.
constexpr char kLeaseLostPayload[] = "type.plenoxd/plx.LeaseLost";
// Marks the UNAVAILABLE of a recorded handoff request (IsHandoffRequested), told apart from a
// storage that is unreachable.
constexpr char kHandoffPayload[] = "type.plenoxd/plx.HandoffRequested";

std::string SecondsText(absl::Duration d) {
  return absl::StrFormat("%.1f s", absl::ToDoubleSeconds(d));
}

absl::Status LeaseLostError(absl::string_view map, uint64_t held_token,
                            const LeaseRecord& current) {
  absl::Status status = absl::FailedPreconditionError(absl::StrCat(
      "map \"", map, "\" is no longer owned by this daemon: its lease (generation ", held_token,
      ") was taken over by generation ", current.token, " (holder ", current.holder,
      "); nothing more is written here; call the map's owner"));
  status.SetPayload(kLeaseLostPayload, absl::Cord("1"));
  return status;
}

// A free lease reserved for another daemon's pending request.
bool ReservedForAnother(const LeaseRecord& lease, absl::string_view holder, absl::Time now) {
  return LeaseFree(lease, now) && HandoffPending(lease, holder, now);
}

absl::Status MovingError(absl::string_view map, const LeaseRecord& lease, absl::Time now) {
  return absl::UnavailableError(absl::StrCat(
      "map \"", map, "\" is moving to daemon ", lease.wanted_by, " (its previous owner released "
      "it for that daemon, for ", SecondsText(lease.wanted_until - now),
      " more); call that daemon"));
}

}  // namespace

LeaseTerms LeaseTermsFor(absl::Duration term) {
  LeaseTerms terms;
  terms.term = term;
  terms.renew_every = term / 3;
  terms.write_margin = term / 4;
  terms.handoff_quiet = term / 3;
  terms.handoff_wait = term;
  return terms;
}

std::string MakeHolderId(absl::string_view host, int64_t pid, uint64_t random) {
  std::string clean(host.substr(0, 64));
  for (char& c : clean) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_';
    if (!ok) c = '_';
  }
  if (clean.empty()) clean = "host";
  return absl::StrFormat("%s-%d-%016x", clean, pid, random);
}

bool LeaseFree(const LeaseRecord& lease, absl::Time now) {
  return lease.token == 0 || lease.holder.empty() || lease.expires <= now;
}

absl::StatusOr<LeaseRecord> NextLease(absl::string_view map, const LeaseRecord& current,
                                      absl::string_view holder, uint64_t held_token,
                                      absl::Time now, const LeaseTerms& terms) {
  LeaseRecord next = current;
  next.holder = std::string(holder);
  next.expires = now + terms.term;
  if (held_token != 0) {
    // A renewal: only of the very record this holder took. Expired but untouched is fine
    // (nobody else held the map since); any other token means someone took it over.
    if (current.holder != holder || current.token != held_token) {
      return LeaseLostError(map, held_token, current);
    }
    return next;
  }
  // A take clears any request: its requester has the map, or a newer router view wins.
  next.wanted_by.clear();
  next.wanted_until = absl::InfinitePast();
  if (!LeaseFree(current, now)) {
    if (current.holder == holder) {
      // Our own live lease, but the caller holds nothing under it (a map dropped and asked
      // for again): taken anew, so whatever used the old token is fenced off too.
      next.token = current.token + 1;
      return next;
    }
    return absl::FailedPreconditionError(absl::StrCat(
        "map \"", map, "\" is owned by another daemon (lease generation ", current.token,
        ", holder ", current.holder, ", for ", SecondsText(current.expires - now),
        " more unless renewed); call that daemon"));
  }
  if (ReservedForAnother(current, holder, now)) return MovingError(map, current, now);
  next.token = current.token + 1;
  return next;
}

absl::Status CheckFence(absl::string_view map, const LeaseRecord& current,
                        absl::string_view holder, uint64_t token, absl::Time now,
                        const LeaseTerms& terms) {
  if (token == 0 || current.holder != holder || current.token != token) {
    return LeaseLostError(map, token, current);
  }
  if (current.expires - now < terms.write_margin) {
    return absl::FailedPreconditionError(absl::StrCat(
        "map \"", map, "\": this daemon's lease (generation ", token, ") ",
        current.expires <= now ? "expired " : "is about to expire, ",
        current.expires <= now ? absl::StrCat(SecondsText(now - current.expires), " ago")
                               : absl::StrCat(SecondsText(current.expires - now), " left"),
        ", not renewed in time; nothing was written (a renewal may still keep the map)"));
  }
  return absl::OkStatus();
}

LeaseRecord ReleasedLease(const LeaseRecord& current) {
  LeaseRecord released = current;
  released.expires = absl::UnixEpoch();
  return released;
}

bool IsLeaseLost(const absl::Status& status) {
  return status.GetPayload(kLeaseLostPayload).has_value();
}

bool HandoffPending(const LeaseRecord& lease, absl::string_view holder, absl::Time now) {
  return !lease.wanted_by.empty() && lease.wanted_by != holder && lease.wanted_until > now;
}

absl::StatusOr<LeaseRecord> RequestHandoff(absl::string_view map, const LeaseRecord& current,
                                           absl::string_view requester, absl::Time now,
                                           const LeaseTerms& terms) {
  if (LeaseFree(current, now)) {
    if (ReservedForAnother(current, requester, now)) return MovingError(map, current, now);
    return absl::FailedPreconditionError(
        absl::StrCat("map \"", map, "\": its lease is free; take it, no handoff is needed"));
  }
  if (current.holder == requester) {
    return absl::FailedPreconditionError(
        absl::StrCat("map \"", map, "\": the requester holds its lease already"));
  }
  LeaseRecord next = current;
  next.wanted_by = std::string(requester);
  next.wanted_until = now + terms.handoff_wait;
  return next;
}

absl::Status HandoffRequestedError(absl::string_view map, const LeaseRecord& current,
                                   const LeaseTerms& terms) {
  absl::Status status = absl::UnavailableError(absl::StrCat(
      "map \"", map, "\" is owned by another daemon (lease generation ", current.token,
      ", holder ", current.holder, "); asked it to hand the map over to this daemon, which it "
      "does (saving it) once no mapping job holds it and no call has named it for ",
      SecondsText(terms.handoff_quiet), "; retry"));
  status.SetPayload(kHandoffPayload, absl::Cord("1"));
  return status;
}

bool IsHandoffRequested(const absl::Status& status) {
  return status.GetPayload(kHandoffPayload).has_value();
}

bool ShouldHandOff(bool mapping, absl::Time last_call, absl::Time now, const LeaseTerms& terms) {
  return !mapping && now - last_call >= terms.handoff_quiet;
}

}  // namespace plx
