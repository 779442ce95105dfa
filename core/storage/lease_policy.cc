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

}  // namespace

LeaseTerms LeaseTermsFor(absl::Duration term) {
  LeaseTerms terms;
  terms.term = term;
  terms.renew_every = term / 3;
  terms.write_margin = term / 4;
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

}  // namespace plx
