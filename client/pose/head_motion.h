// A synthetic head-motion generator: a person standing and looking around
// (head turns between fixations with minimum-jerk velocity profiles, as
// measured head movements have; slow postural sway; the eye offset from the
// neck pivot, so turning the head also moves the eye) or walking about
// (minimum-jerk walks between waypoints, heading following the path, vertical
// bob at the step frequency and lateral sway at the stride frequency, looking
// around on top). Deterministic for a seed. The samples are what a tracker
// would report: the true pose plus small white noise.
#pragma once

#include <cstdint>
#include <vector>

#include "client/pose/head_pose.h"
#include "common/status.h"

namespace holo::pose {

enum class HeadMotionKind { kLookAround, kWalk };

struct HeadMotionOptions {
  HeadMotionKind kind = HeadMotionKind::kLookAround;
  uint64_t seed = 1;
  // Tracker rate, Hz, and length, seconds.
  double rate_hz = 90.0;
  double duration_s = 30.0;
  // Gaze targets: yaw uniform in ±yaw_range_deg around yaw 0 (world +x),
  // pitch normal with σ pitch_sigma_deg (clamped to ±3σ).
  double yaw_range_deg = 35.0;
  double pitch_sigma_deg = 8.0;
  // Fixation time between turns: min + exponential with this mean, s.
  double fixation_min_s = 0.25;
  double fixation_mean_s = 0.7;
  // Head-turn duration = turn_base_s + amplitude / turn_rate_deg_s (peak
  // angular velocity of a minimum-jerk turn is 1.875 × amplitude / duration:
  // ~190°/s for a 60° turn at the defaults).
  double turn_base_s = 0.2;
  double turn_rate_deg_s = 150.0;
  // Standing eye position (metres) before sway; the neck pivot sits
  // eye_offset below and behind it.
  Eigen::Vector3d stand_position{0.0, 0.0, 1.65};
  // Postural sway amplitude (horizontal, vertical), metres.
  double sway_m = 0.012;
  double sway_vertical_m = 0.004;
  // Walking: waypoints uniform in a square of this half size around the
  // stand position, speed m/s, step frequency Hz, bob and lateral sway (m).
  double walk_half_extent_m = 1.0;
  double walk_speed_m_s = 1.1;
  double step_hz = 1.9;
  double bob_m = 0.015;
  double lateral_sway_m = 0.02;
  // Tracker noise (white, per sample): position σ metres, angle σ degrees.
  double position_noise_m = 0.0003;
  double angle_noise_deg = 0.03;
  Status Check() const;
};

// The tracker samples at 1/rate_hz intervals from time 0, and the same
// motion without tracker noise (the truth) if `truth` is not null.
StatusOr<std::vector<PoseSample>> GenerateHeadMotion(const HeadMotionOptions& options,
                                                     std::vector<PoseSample>* truth = nullptr);

}  // namespace holo::pose
