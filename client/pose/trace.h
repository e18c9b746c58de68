// Recorded head traces: CSV files with one pose per line,
//   time_s, x_m, y_m, z_m, yaw_deg, pitch_deg, roll_deg
// time in seconds (strictly increasing), position in metres, angles in
// degrees (head_pose.h gives the frame and the Euler convention). Blank lines
// and lines starting with '#' are ignored; the first other line may be a
// header (any line whose first field is not a number). Safe on untrusted input.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "client/pose/head_pose.h"
#include "common/status.h"

namespace holo::pose {

struct TraceLimits {
  size_t max_bytes = 64u << 20;     // file size
  size_t max_samples = 1u << 22;    // lines with a pose
  double max_abs_position_m = 1000;
  double max_abs_yaw_deg = 36000;   // yaw may be unwrapped (many turns)
  double max_abs_roll_deg = 180;
  // Pitch beyond ±90° is not a head pose in this convention.
  double max_abs_pitch_deg = 90;
  double max_duration_s = 7 * 24 * 3600.0;
};

// Parses CSV `text`; `name` prefixes every error ("head.csv:12: field 4
// (yaw_deg): 'abc' is not a number"). InvalidArgument for: a line without
// exactly 7 fields, a field that is not a finite number, a value out of the
// limits, a time not after the previous one, no pose at all.
StatusOr<std::vector<PoseSample>> ParseHeadTrace(std::string_view text, const std::string& name,
                                                 const TraceLimits& limits = {});
// Reads and parses a file (NotFound / DataLoss if it cannot be read).
StatusOr<std::vector<PoseSample>> ReadHeadTrace(const std::string& path, const TraceLimits& limits = {});

// CSV text of `samples` with a header line and `comment` lines ('#' added).
// Times are written relative to nothing (µs → s with 6 decimals); positions
// with 5 decimals (10 µm), angles with 4 (0.0001°).
std::string FormatHeadTrace(const std::vector<PoseSample>& samples, const std::vector<std::string>& comment = {});
Status WriteHeadTrace(const std::string& path, const std::vector<PoseSample>& samples,
                      const std::vector<std::string>& comment = {});

}  // namespace holo::pose
