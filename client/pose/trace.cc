#include "client/pose/trace.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace holo::pose {
namespace {

constexpr const char* kFieldNames[7] = {"time_s", "x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg"};
constexpr double kDegToRad = M_PI / 180.0;

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// Whole-field parse of a finite double.
bool ParseDouble(std::string_view field, double* out) {
  if (field.empty() || field.size() > 64) return false;
  const std::string s(field);
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size() || errno == ERANGE || !std::isfinite(v)) return false;
  *out = v;
  return true;
}

std::string Shorten(std::string_view s) {
  if (s.size() <= 40) return std::string(s);
  return std::string(s.substr(0, 37)) + "...";
}

}  // namespace

StatusOr<std::vector<PoseSample>> ParseHeadTrace(std::string_view text, const std::string& name,
                                                 const TraceLimits& limits) {
  if (text.size() > limits.max_bytes) {
    return InvalidArgument(name + ": " + std::to_string(text.size()) + " bytes exceeds the limit of " +
                           std::to_string(limits.max_bytes));
  }
  std::vector<PoseSample> samples;
  size_t line_no = 0;
  bool seen_data_or_header = false;
  double first_time = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    const std::string_view line = Trim(text.substr(pos, eol - pos));
    pos = eol + 1;
    ++line_no;
    if (line.empty() || line.front() == '#') continue;
    const std::string where = name + ":" + std::to_string(line_no) + ": ";
    std::string_view fields[7];
    size_t count = 0;
    size_t start = 0;
    while (true) {
      const size_t comma = line.find(',', start);
      const std::string_view f = Trim(line.substr(start, comma == std::string_view::npos ? line.npos : comma - start));
      if (count < 7) fields[count] = f;
      ++count;
      if (comma == std::string_view::npos) break;
      start = comma + 1;
    }
    double v[7];
    if (!seen_data_or_header) {
      seen_data_or_header = true;
      if (!ParseDouble(fields[0], &v[0])) continue;  // header line
    }
    if (count != 7) {
      return InvalidArgument(where + "expected 7 fields (time_s, x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg), got " +
                             std::to_string(count));
    }
    for (int i = 0; i < 7; ++i) {
      if (!ParseDouble(fields[i], &v[i])) {
        return InvalidArgument(where + "field " + std::to_string(i + 1) + " (" + kFieldNames[i] + "): '" +
                               Shorten(fields[i]) + "' is not a finite number");
      }
    }
    const double bounds[7] = {1e10 /* s: allows Unix times */, limits.max_abs_position_m, limits.max_abs_position_m,
                              limits.max_abs_position_m, limits.max_abs_yaw_deg, limits.max_abs_pitch_deg,
                              limits.max_abs_roll_deg};
    for (int i = 0; i < 7; ++i) {
      if (std::abs(v[i]) > bounds[i]) {
        return InvalidArgument(where + "field " + std::to_string(i + 1) + " (" + kFieldNames[i] + "): " +
                               Shorten(fields[i]) + " is out of range (|value| <= " + Shorten(std::to_string(bounds[i])) +
                               ")");
      }
    }
    if (samples.empty()) first_time = v[0];
    if (v[0] - first_time > limits.max_duration_s) {
      return InvalidArgument(where + "field 1 (time_s): the trace is longer than " +
                             std::to_string(limits.max_duration_s) + " s");
    }
    PoseSample s;
    s.time_us = std::llround(v[0] * 1e6);
    if (!samples.empty() && s.time_us <= samples.back().time_us) {
      return InvalidArgument(where + "field 1 (time_s): " + Shorten(fields[0]) +
                             " is not after the previous sample's time (" +
                             std::to_string(samples.back().time_us * 1e-6) + " s)");
    }
    if (samples.size() >= limits.max_samples) {
      return InvalidArgument(where + "more than " + std::to_string(limits.max_samples) + " samples");
    }
    s.position = Eigen::Vector3d(v[1], v[2], v[3]);
    s.rotation = RotationFromYawPitchRoll(v[4] * kDegToRad, v[5] * kDegToRad, v[6] * kDegToRad);
    samples.push_back(s);
  }
  if (samples.empty()) return InvalidArgument(name + ": no pose samples");
  return samples;
}

StatusOr<std::vector<PoseSample>> ReadHeadTrace(const std::string& path, const TraceLimits& limits) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return NotFound(path + ": cannot open");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) return DataLoss(path + ": cannot read");
  if (static_cast<uint64_t>(size) > limits.max_bytes) {
    return InvalidArgument(path + ": " + std::to_string(size) + " bytes exceeds the limit of " +
                           std::to_string(limits.max_bytes));
  }
  in.seekg(0);
  std::string text(static_cast<size_t>(size), '\0');
  if (!in.read(text.data(), size)) return DataLoss(path + ": read failed");
  return ParseHeadTrace(text, path, limits);
}

std::string FormatHeadTrace(const std::vector<PoseSample>& samples, const std::vector<std::string>& comment) {
  std::string out;
  for (const std::string& c : comment) out += "# " + c + "\n";
  out += "time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg\n";
  char buf[256];
  for (const PoseSample& s : samples) {
    const Eigen::Vector3d ypr = YawPitchRollFromRotation(s.rotation) / kDegToRad;
    std::snprintf(buf, sizeof(buf), "%.6f,%.5f,%.5f,%.5f,%.4f,%.4f,%.4f\n", s.time_us * 1e-6, s.position.x(),
                  s.position.y(), s.position.z(), ypr.x(), ypr.y(), ypr.z());
    out += buf;
  }
  return out;
}

Status WriteHeadTrace(const std::string& path, const std::vector<PoseSample>& samples,
                      const std::vector<std::string>& comment) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return Unavailable(path + ": cannot open for writing");
  const std::string text = FormatHeadTrace(samples, comment);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  if (!out) return DataLoss(path + ": write failed");
  return OkStatus();
}

}  // namespace holo::pose
