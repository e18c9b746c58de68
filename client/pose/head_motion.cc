#include "client/pose/head_motion.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

namespace holo::pose {
namespace {

constexpr double kDeg = M_PI / 180.0;

double MinJerk(double u) {
  u = std::clamp(u, 0.0, 1.0);
  return u * u * u * (10.0 - 15.0 * u + 6.0 * u * u);
}

// A piecewise schedule of minimum-jerk moves of a vector quantity, holding
// still between moves.
template <int N>
struct Schedule {
  using Vec = Eigen::Matrix<double, N, 1>;
  struct Move {
    double t0, duration;
    Vec from, to;
  };
  std::vector<Move> moves;  // time-ordered, non-overlapping
  Vec initial = Vec::Zero();

  Vec At(double t) const {
    // Last move starting at or before t.
    auto it = std::upper_bound(moves.begin(), moves.end(), t, [](double x, const Move& m) { return x < m.t0; });
    if (it == moves.begin()) return initial;
    const Move& m = *(it - 1);
    return m.from + MinJerk((t - m.t0) / m.duration) * (m.to - m.from);
  }
};

// Smooth drift: a few sinusoids per axis with random phases.
struct Drift {
  struct Wave {
    double amp, freq, phase;
  };
  std::vector<Wave> waves[3];
  Eigen::Vector3d At(double t) const {
    Eigen::Vector3d v = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a) {
      for (const Wave& w : waves[a]) v[a] += w.amp * std::sin(2 * M_PI * w.freq * t + w.phase);
    }
    return v;
  }
};

Drift MakeDrift(std::mt19937_64& rng, const Eigen::Vector3d& amplitude, double f_lo, double f_hi) {
  std::uniform_real_distribution<double> freq(f_lo, f_hi), phase(0, 2 * M_PI), share(0.5, 1.0);
  Drift d;
  for (int a = 0; a < 3; ++a) {
    for (int k = 0; k < 3; ++k) d.waves[a].push_back({amplitude[a] * share(rng) / 2.0, freq(rng), phase(rng)});
  }
  return d;
}

// Gaze (yaw, pitch, roll offsets, radians): fixations and head turns.
Schedule<3> MakeGazeSchedule(const HeadMotionOptions& o, std::mt19937_64& rng, double yaw_range_deg) {
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::exponential_distribution<double> fixation(1.0 / o.fixation_mean_s);
  std::normal_distribution<double> pitch(0.0, o.pitch_sigma_deg), roll(0.0, 2.0);
  Schedule<3> s;
  Eigen::Vector3d cur = Eigen::Vector3d::Zero();
  double t = o.fixation_min_s + fixation(rng);
  while (t < o.duration_s + 2.0) {
    Eigen::Vector3d next;
    if (uni(rng) < 0.35) {  // a small correction near the current target
      const double sign = uni(rng) < 0.5 ? -1 : 1;
      next = cur + Eigen::Vector3d(sign * (2 + 6 * uni(rng)), 3 * (uni(rng) - 0.5), 0.5 * (uni(rng) - 0.5)) * kDeg;
      next.x() = std::clamp(next.x(), -yaw_range_deg * kDeg, yaw_range_deg * kDeg);
    } else {
      const double p = std::clamp(pitch(rng), -3 * o.pitch_sigma_deg, 3 * o.pitch_sigma_deg);
      next = Eigen::Vector3d(yaw_range_deg * (2 * uni(rng) - 1), p, std::clamp(roll(rng), -6.0, 6.0)) * kDeg;
    }
    const double amplitude_deg = (next - cur).head<2>().norm() / kDeg;
    const double duration = o.turn_base_s + amplitude_deg / o.turn_rate_deg_s;
    s.moves.push_back({t, duration, cur, next});
    cur = next;
    t += duration + o.fixation_min_s + fixation(rng);
  }
  return s;
}

}  // namespace

Status HeadMotionOptions::Check() const {
  auto positive = [](double v, const char* name) -> Status {
    if (!(v > 0) || !std::isfinite(v)) return InvalidArgument(std::string(name) + " must be > 0, got " + std::to_string(v));
    return OkStatus();
  };
  HOLO_RETURN_IF_ERROR(positive(rate_hz, "rate_hz"));
  HOLO_RETURN_IF_ERROR(positive(duration_s, "duration_s"));
  HOLO_RETURN_IF_ERROR(positive(fixation_mean_s, "fixation_mean_s"));
  HOLO_RETURN_IF_ERROR(positive(turn_rate_deg_s, "turn_rate_deg_s"));
  HOLO_RETURN_IF_ERROR(positive(walk_speed_m_s, "walk_speed_m_s"));
  HOLO_RETURN_IF_ERROR(positive(walk_half_extent_m, "walk_half_extent_m"));
  if (rate_hz > 10000) return InvalidArgument("rate_hz must be <= 10000, got " + std::to_string(rate_hz));
  if (duration_s * rate_hz > 1e7) return InvalidArgument("duration_s × rate_hz must be <= 1e7 samples");
  if (!(yaw_range_deg >= 0 && yaw_range_deg <= 170)) return InvalidArgument("yaw_range_deg must be in [0, 170]");
  if (!(pitch_sigma_deg >= 0 && pitch_sigma_deg <= 25)) return InvalidArgument("pitch_sigma_deg must be in [0, 25]");
  if (!(fixation_min_s >= 0) || !(turn_base_s > 0)) return InvalidArgument("fixation_min_s must be >= 0 and turn_base_s > 0");
  for (double v : {sway_m, sway_vertical_m, bob_m, lateral_sway_m, position_noise_m, angle_noise_deg, step_hz}) {
    if (!(v >= 0) || !std::isfinite(v)) return InvalidArgument("sway, bob, noise and step_hz values must be >= 0");
  }
  if (!stand_position.allFinite()) return InvalidArgument("stand_position must be finite");
  return OkStatus();
}

StatusOr<std::vector<PoseSample>> GenerateHeadMotion(const HeadMotionOptions& o, std::vector<PoseSample>* truth) {
  HOLO_RETURN_IF_ERROR(o.Check());
  std::mt19937_64 rng(o.seed * 0x9e3779b97f4a7c15ULL + 17);
  const bool walk = o.kind == HeadMotionKind::kWalk;
  const Schedule<3> gaze = MakeGazeSchedule(o, rng, walk ? 0.6 * o.yaw_range_deg : o.yaw_range_deg);
  const Drift angle_drift = MakeDrift(rng, Eigen::Vector3d(0.6, 0.4, 0.3) * kDeg, 0.15, 1.2);
  const Drift sway = MakeDrift(rng, Eigen::Vector3d(o.sway_m, o.sway_m, o.sway_vertical_m), 0.08, 0.5);
  // Eye relative to the neck pivot, head frame (x forward, y left, z up).
  const Eigen::Vector3d eye_offset(0.08, 0.0, 0.10);

  // Walking: body position (x, y) and body yaw schedules: turn towards the
  // next waypoint, walk there, pause.
  Schedule<2> body_xy;
  Schedule<1> body_yaw;
  body_xy.initial = o.stand_position.head<2>();
  if (walk) {
    std::uniform_real_distribution<double> uni(-1.0, 1.0), pause(0.4, 2.0);
    Eigen::Vector2d at = o.stand_position.head<2>();
    double yaw = 0, t = pause(rng);
    while (t < o.duration_s + 2.0) {
      Eigen::Vector2d to;
      do {
        to = o.stand_position.head<2>() + o.walk_half_extent_m * Eigen::Vector2d(uni(rng), uni(rng));
      } while ((to - at).norm() < 0.5 * o.walk_half_extent_m);
      const Eigen::Vector2d d = to - at;
      double heading = std::atan2(d.y(), d.x());
      while (heading - yaw > M_PI) heading -= 2 * M_PI;
      while (heading - yaw < -M_PI) heading += 2 * M_PI;
      const double turn_s = 0.3 + std::abs(heading - yaw) / (180 * kDeg);
      body_yaw.moves.push_back({t, turn_s, Eigen::Matrix<double, 1, 1>(yaw), Eigen::Matrix<double, 1, 1>(heading)});
      t += 0.6 * turn_s;  // start walking while still turning
      // A minimum-jerk walk peaks at 1.875 × mean speed: pick the duration
      // for the requested peak (cruise) speed.
      const double walk_s = 1.875 * d.norm() / o.walk_speed_m_s;
      body_xy.moves.push_back({t, walk_s, at, to});
      yaw = heading;
      at = to;
      t += walk_s + pause(rng);
    }
  }

  const int64_t n = static_cast<int64_t>(std::floor(o.duration_s * o.rate_hz)) + 1;
  std::vector<PoseSample> out;
  out.reserve(static_cast<size_t>(n));
  if (truth) truth->clear();
  std::normal_distribution<double> pos_noise(0.0, o.position_noise_m), ang_noise(0.0, o.angle_noise_deg * kDeg);
  const double dt_probe = 1e-3;
  for (int64_t i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / o.rate_hz;
    Eigen::Vector3d angles = gaze.At(t) + angle_drift.At(t);  // yaw, pitch, roll offsets
    Eigen::Vector3d neck = o.stand_position - eye_offset + sway.At(t);
    if (walk) {
      angles.x() += body_yaw.At(t)(0);
      const Eigen::Vector2d xy = body_xy.At(t);
      const Eigen::Vector2d v = (body_xy.At(t + dt_probe) - body_xy.At(t - dt_probe)) / (2 * dt_probe);
      const double speed_factor = std::min(1.0, v.norm() / o.walk_speed_m_s);
      const double heading = body_yaw.At(t)(0);
      const Eigen::Vector2d lateral(-std::sin(heading), std::cos(heading));
      neck.head<2>() += xy - o.stand_position.head<2>() +
                        lateral * (o.lateral_sway_m * speed_factor * std::sin(M_PI * o.step_hz * t));
      neck.z() += o.bob_m * speed_factor * std::sin(2 * M_PI * o.step_hz * t);
    }
    const Eigen::Matrix3d world_from_head = (Eigen::AngleAxisd(angles.x(), Eigen::Vector3d::UnitZ()) *
                                             Eigen::AngleAxisd(-angles.y(), Eigen::Vector3d::UnitY()) *
                                             Eigen::AngleAxisd(angles.z(), Eigen::Vector3d::UnitX()))
                                                .toRotationMatrix();
    PoseSample s;
    s.time_us = std::llround(t * 1e6);
    s.position = neck + world_from_head * eye_offset;
    s.rotation = RotationFromYawPitchRoll(angles.x(), angles.y(), angles.z());
    if (truth) truth->push_back(s);
    s.position += Eigen::Vector3d(pos_noise(rng), pos_noise(rng), pos_noise(rng));
    s.rotation = (ExpRotation(Eigen::Vector3d(ang_noise(rng), ang_noise(rng), ang_noise(rng))) * s.rotation).normalized();
    out.push_back(s);
  }
  return out;
}

}  // namespace holo::pose
