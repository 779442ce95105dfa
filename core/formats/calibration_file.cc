#include "core/formats/calibration_file.h"

#include <filesystem>
#include <fstream>
#include <limits>
#include <system_error>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "core/common/status_macros.h"
#include "core/formats/text_table.h"

namespace plx {
namespace {

// Width and height are written as integers; "640.0" would be a typo worth reporting.
absl::StatusOr<int> ParseSizeField(const TextTable& table, const TextRow& row, size_t index) {
  PLX_ASSIGN_OR_RETURN(const int64_t value, ParseIntField(table, row, index));
  if (value <= 0 || value > std::numeric_limits<int>::max()) {
    return LineError(
        table.path, row.line_number,
        absl::StrCat("field ", index + 1, " (image size) must be positive, got ", value));
  }
  return static_cast<int>(value);
}

}  // namespace

absl::StatusOr<CameraCalibration> ReadCalibrationFile(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const TextTable table, ReadTextTable(path));
  if (table.rows.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": no data line; expected \"fx fy cx cy width height depth_scale k1 k2 p1 p2 k3\""));
  }
  if (table.rows.size() > 1) {
    return LineError(path, table.rows[1].line_number,
                     "expected a single data line, found another one");
  }
  const TextRow& row = table.rows[0];
  if (row.fields.size() != 7 && row.fields.size() != 12) {
    return LineError(path, row.line_number,
                     absl::StrCat("expected 12 numbers \"fx fy cx cy width height depth_scale "
                                  "k1 k2 p1 p2 k3\" (or the first 7), got ",
                                  row.fields.size()));
  }
  CameraCalibration calibration;
  PLX_ASSIGN_OR_RETURN(const std::vector<double> k, ParseDoubleFields(table, row, 0, 4));
  calibration.pinhole.fx = k[0];
  calibration.pinhole.fy = k[1];
  calibration.pinhole.cx = k[2];
  calibration.pinhole.cy = k[3];
  PLX_ASSIGN_OR_RETURN(calibration.pinhole.width, ParseSizeField(table, row, 4));
  PLX_ASSIGN_OR_RETURN(calibration.pinhole.height, ParseSizeField(table, row, 5));
  PLX_ASSIGN_OR_RETURN(calibration.depth_scale, ParseDoubleField(table, row, 6));
  if (row.fields.size() == 12) {
    PLX_ASSIGN_OR_RETURN(const std::vector<double> d, ParseDoubleFields(table, row, 7, 5));
    calibration.distortion = Distortion{d[0], d[1], d[2], d[3], d[4]};
  }
  if (absl::Status status = ValidateCalibration(calibration); !status.ok()) {
    return LineError(path, row.line_number, status.message());
  }
  return calibration;
}

std::string FormatCalibrationFile(const CameraCalibration& c) {
  const PinholeIntrinsics& k = c.pinhole;
  const Distortion& d = c.distortion;
  std::vector<std::string> fields = {
      FormatShortest(k.fx),          FormatShortest(k.fy),  FormatShortest(k.cx),
      FormatShortest(k.cy),          absl::StrCat(k.width), absl::StrCat(k.height),
      FormatShortest(c.depth_scale), FormatShortest(d.k1),  FormatShortest(d.k2),
      FormatShortest(d.p1),          FormatShortest(d.p2),  FormatShortest(d.k3)};
  return absl::StrCat("# fx fy cx cy width height depth_scale k1 k2 p1 p2 k3\n",
                      absl::StrJoin(fields, " "), "\n");
}

absl::Status WriteCalibrationFile(const std::string& path, const CameraCalibration& calibration) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) return absl::PermissionDeniedError(absl::StrCat(path, ": cannot open for writing"));
  out << FormatCalibrationFile(calibration);
  out.close();
  if (!out) return absl::DataLossError(absl::StrCat(path, ": write failed"));
  return absl::OkStatus();
}

absl::Status MissingCalibrationError(const std::string& directory) {
  return absl::NotFoundError(absl::StrCat(
      "no calibration for ", directory, ": ", kCalibrationFileName,
      " is missing (expected one line \"fx fy cx cy width height depth_scale k1 k2 p1 p2 k3\"); "
      "create it or provide the calibration with command-line flags (--intrinsics "
      "\"fx fy cx cy w h\" and the depth scale)"));
}

absl::StatusOr<CameraCalibration> LoadDatasetCalibration(
    const std::string& directory, const std::optional<CameraCalibration>& override_calibration) {
  if (override_calibration.has_value()) {
    if (absl::Status status = ValidateCalibration(*override_calibration); !status.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("calibration given by flags: ", status.message()));
    }
    return *override_calibration;
  }
  const std::string path = (std::filesystem::path(directory) / kCalibrationFileName).string();
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return MissingCalibrationError(directory);
  return ReadCalibrationFile(path);
}

absl::StatusOr<PinholeIntrinsics> ReadIntrinsicMatrixFile(const std::string& path) {
  PLX_ASSIGN_OR_RETURN(const TextTable table, ReadTextTable(path));
  if (table.rows.size() != 3 && table.rows.size() != 4) {
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": expected a 4x4 (or 3x3) camera matrix, got ", table.rows.size(), " rows"));
  }
  const size_t columns = table.rows.size();
  double m[3][3];
  for (int r = 0; r < 3; ++r) {
    const TextRow& row = table.rows[r];
    PLX_RETURN_IF_ERROR(ExpectFieldCount(table, row, columns, "numbers"));
    PLX_ASSIGN_OR_RETURN(const std::vector<double> values, ParseDoubleFields(table, row, 0, 3));
    for (int c = 0; c < 3; ++c) m[r][c] = values[c];
  }
  for (size_t r = 3; r < table.rows.size(); ++r) {
    PLX_RETURN_IF_ERROR(ExpectFieldCount(table, table.rows[r], columns, "numbers"));
  }
  PinholeIntrinsics k;
  k.fx = m[0][0];
  k.fy = m[1][1];
  k.cx = m[0][2];
  k.cy = m[1][2];
  if (!(k.fx > 0 && k.fy > 0)) {
    return LineError(path, table.rows[0].line_number,
                     absl::StrCat("focal lengths must be positive, got fx=", k.fx, " fy=", k.fy));
  }
  return k;
}

}  // namespace plx
