#include "core/formats/trajectory_file.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "absl/strings/string_view.h"
#include "core/common/status_macros.h"
#include "core/formats/text_table.h"
#include "core/io/atomic_write.h"

namespace plx {
namespace {

// Below this norm a quaternion has no usable direction (a line of zeros, or a misplaced column).
constexpr double kMinQuaternionNorm = 1e-6;

// A pose with the line it came from, for the duplicate-timestamp message after sorting.
struct ParsedPose {
  StampedPose stamped;
  int line_number = 0;
};

std::string FormatLine(const StampedPose& p) {
  Eigen::Quaterniond q = p.pose.rotation();
  // q and -q are the same rotation; pick the one with qw >= 0 so files diff cleanly.
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Eigen::Vector3d& t = p.pose.translation();
  return absl::StrFormat("%.6f %.9g %.9g %.9g %.9g %.9g %.9g %.9g\n", p.timestamp, t.x(), t.y(),
                         t.z(), q.x(), q.y(), q.z(), q.w());
}

}  // namespace

absl::StatusOr<std::vector<StampedPose>> ReadTumTrajectory(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const TextTable table, ReadTextTable(path));
  std::vector<ParsedPose> parsed;
  parsed.reserve(table.rows.size());
  for (const TextRow& row : table.rows) {
    PLX_RETURN_IF_ERROR(
        ExpectFieldCount(table, row, 8, "numbers (timestamp tx ty tz qx qy qz qw)"));
    PLX_ASSIGN_OR_RETURN(const std::vector<double> v, ParseDoubleFields(table, row, 0, 8));
    const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);  // file order: qx qy qz qw
    const std::optional<Eigen::Quaterniond> unit = UnitQuaternion(q, kMinQuaternionNorm);
    if (!unit) {
      return LineError(table.path, row.line_number,
                       absl::StrCat("the quaternion qx qy qz qw is zero (norm ", q.norm(), ")"));
    }
    ParsedPose p;
    p.stamped.timestamp = v[0];
    p.stamped.pose = SE3(*unit, Eigen::Vector3d(v[1], v[2], v[3]));
    p.line_number = row.line_number;
    parsed.push_back(p);
  }
  // Files are normally in time order already; a stable sort keeps equal stamps in file order so
  // the duplicate message names the earlier line first.
  std::stable_sort(parsed.begin(), parsed.end(), [](const ParsedPose& a, const ParsedPose& b) {
    return a.stamped.timestamp < b.stamped.timestamp;
  });
  std::vector<StampedPose> poses;
  poses.reserve(parsed.size());
  for (size_t i = 0; i < parsed.size(); ++i) {
    if (i > 0 && parsed[i].stamped.timestamp == parsed[i - 1].stamped.timestamp) {
      return LineError(table.path, parsed[i].line_number,
                       absl::StrCat("duplicate timestamp ",
                                    FormatShortest(parsed[i].stamped.timestamp),
                                    " (also on line ", parsed[i - 1].line_number, ")"));
    }
    poses.push_back(parsed[i].stamped);
  }
  return poses;
}

absl::Status WriteTumTrajectory(const std::string& path, const std::vector<StampedPose>& poses,
                                const std::string& header_comment) {
  const std::string what = absl::StrCat("cannot write trajectory ", path);

  std::string text;
  if (!header_comment.empty()) {
    // A trailing newline ends the last line rather than adding an empty one.
    const absl::string_view header = absl::StripSuffix(header_comment, "\n");
    for (absl::string_view line : absl::StrSplit(header, '\n')) {
      absl::StrAppend(&text, "#", line.empty() ? "" : " ", line, "\n");
    }
  }
  double previous_written = 0.0;
  for (size_t i = 0; i < poses.size(); ++i) {
    const StampedPose& p = poses[i];
    if (!std::isfinite(p.timestamp) || !p.pose.IsFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": pose ", i, " (timestamp ", p.timestamp, ") is not finite"));
    }
    const std::string line = FormatLine(p);
    // The timestamp as the reader will see it: compare those, not the doubles, so that two
    // stamps closer than the printed microsecond are caught here rather than when reading.
    double written = 0.0;
    if (!absl::SimpleAtod(line.substr(0, line.find(' ')), &written)) {
      return absl::InternalError(absl::StrCat(what, ": cannot format timestamp ", p.timestamp));
    }
    if (i > 0 && written <= previous_written) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s: timestamps must increase by at least 1 us (the written precision); pose %d at "
          "%.6f follows %.6f",
          what, i, p.timestamp, poses[i - 1].timestamp));
    }
    previous_written = written;
    text += line;
  }

  return WriteFileAtomically(path, text, what);
}

}  // namespace plx
