#include "client/pose/predictor.h"

#include <algorithm>
#include <cmath>

namespace holo::pose {
namespace {

constexpr double kDeg = M_PI / 180.0;

class NonePredictor final : public PosePredictor {
 public:
  bool Observe(const PoseSample& s) override {
    if (has_ && s.time_us <= last_.time_us) return false;
    last_ = s;
    has_ = true;
    return true;
  }
  PoseSample Predict(int64_t time_us) const override {
    HOLO_CHECK_MSG(has_, "Predict before any sample");
    PoseSample out = last_;
    out.time_us = std::max(time_us, last_.time_us);
    return out;
  }
  void Reset() override { has_ = false; }
  PredictorModel model() const override { return PredictorModel::kNone; }

 private:
  PoseSample last_;
  bool has_ = false;
};

// Least-squares line through the window, in the newest sample's tangent space.
class ConstantVelocityPredictor final : public PosePredictor {
 public:
  explicit ConstantVelocityPredictor(const PredictorOptions& o) : options_(o) {}

  bool Observe(const PoseSample& s) override {
    if (!window_.empty() && s.time_us <= window_.back().time_us) return false;
    window_.push_back(s);
    const int64_t window_us = std::llround(options_.window_s * 1e6);
    while (window_.size() > 2 && s.time_us - window_.front().time_us > window_us) window_.pop_front();
    Fit();
    return true;
  }

  PoseSample Predict(int64_t time_us) const override {
    HOLO_CHECK_MSG(!window_.empty(), "Predict before any sample");
    const PoseSample& newest = window_.back();
    const double h = std::clamp((time_us - newest.time_us) * 1e-6, 0.0, options_.max_horizon_s);
    PoseSample out;
    out.time_us = std::max(time_us, newest.time_us);
    out.position = p0_ + h * v_;
    out.rotation = (ExpRotation(r0_ + h * w_) * newest.rotation).normalized();
    return out;
  }
  void Reset() override { window_.clear(); }
  PredictorModel model() const override { return PredictorModel::kConstantVelocity; }

 private:
  void Fit() {
    const PoseSample& newest = window_.back();
    const size_t n = window_.size();
    if (n == 1) {
      p0_ = newest.position;
      v_.setZero();
      r0_.setZero();
      w_.setZero();
      return;
    }
    // Times relative to the newest sample, seconds.
    double st = 0, stt = 0;
    Eigen::Vector3d sp = Eigen::Vector3d::Zero(), stp = Eigen::Vector3d::Zero();
    Eigen::Vector3d sr = Eigen::Vector3d::Zero(), str = Eigen::Vector3d::Zero();
    const Eigen::Quaterniond inv_newest = newest.rotation.conjugate();
    for (const PoseSample& s : window_) {
      const double t = (s.time_us - newest.time_us) * 1e-6;
      const Eigen::Vector3d r = LogRotation(s.rotation * inv_newest);  // world frame
      st += t;
      stt += t * t;
      sp += s.position;
      stp += t * s.position;
      sr += r;
      str += t * r;
    }
    const double dn = static_cast<double>(n);
    const double det = dn * stt - st * st;
    v_ = (dn * stp - st * sp) / det;
    p0_ = (sp - st * v_) / dn;
    w_ = (dn * str - st * sr) / det;
    r0_ = (sr - st * w_) / dn;
  }

  PredictorOptions options_;
  std::deque<PoseSample> window_;
  Eigen::Vector3d p0_, v_, r0_, w_;
};

// One axis of a damped-acceleration (Singer) Kalman filter: state (value,
// velocity, acceleration).
struct AxisFilter {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  Eigen::Matrix3d p = Eigen::Matrix3d::Zero();

  static Eigen::Matrix3d Transition(double dt, double tau) {
    const double e = std::exp(-dt / tau);
    Eigen::Matrix3d f;
    f << 1, dt, tau * (dt - tau * (1 - e)),  //
        0, 1, tau * (1 - e),                 //
        0, 0, e;
    return f;
  }
  void Predict(double dt, double tau, double jerk_psd) {
    const Eigen::Matrix3d f = Transition(dt, tau);
    const double d2 = dt * dt, d3 = d2 * dt, d4 = d3 * dt, d5 = d4 * dt;
    Eigen::Matrix3d q;
    q << d5 / 20, d4 / 8, d3 / 6,  //
        d4 / 8, d3 / 3, d2 / 2,    //
        d3 / 6, d2 / 2, dt;
    x = f * x;
    p = f * p * f.transpose() + jerk_psd * q;
  }
  void Update(double z, double r) {
    const double s = p(0, 0) + r;
    const Eigen::Vector3d k = p.col(0) / s;
    x += k * (z - x(0));
    p -= k * p.row(0);
    p = 0.5 * (p + p.transpose());
  }
};

class KalmanPredictor final : public PosePredictor {
 public:
  explicit KalmanPredictor(const PredictorOptions& o) : options_(o) {}

  bool Observe(const PoseSample& s) override {
    if (has_ && s.time_us <= time_us_) return false;
    const double r_pos = options_.position_sigma_m * options_.position_sigma_m;
    const double r_ang = options_.angle_sigma_rad * options_.angle_sigma_rad;
    if (!has_) {
      q_ = s.rotation.normalized();
      for (int a = 0; a < 3; ++a) {
        pos_[a].x = Eigen::Vector3d(s.position[a], 0, 0);
        pos_[a].p = Eigen::Vector3d(r_pos, 1.0, 25.0).asDiagonal();
        ang_[a].x.setZero();
        ang_[a].p = Eigen::Vector3d(r_ang, 4.0, 400.0).asDiagonal();
      }
      time_us_ = s.time_us;
      has_ = true;
      return true;
    }
    const double dt = (s.time_us - time_us_) * 1e-6;
    time_us_ = s.time_us;
    Eigen::Vector3d dtheta;
    for (int a = 0; a < 3; ++a) {
      pos_[a].Predict(dt, options_.accel_tau_s, options_.position_jerk_psd);
      ang_[a].Predict(dt, options_.accel_tau_s, options_.angle_jerk_psd);
      dtheta[a] = ang_[a].x(0);
      ang_[a].x(0) = 0;
    }
    q_ = (ExpRotation(dtheta) * q_).normalized();
    const Eigen::Vector3d innovation = LogRotation(s.rotation * q_.conjugate());
    for (int a = 0; a < 3; ++a) {
      pos_[a].Update(s.position[a], r_pos);
      ang_[a].Update(innovation[a], r_ang);
      dtheta[a] = ang_[a].x(0);
      ang_[a].x(0) = 0;
    }
    q_ = (ExpRotation(dtheta) * q_).normalized();
    return true;
  }

  PoseSample Predict(int64_t time_us) const override {
    HOLO_CHECK_MSG(has_, "Predict before any sample");
    const double h = std::clamp((time_us - time_us_) * 1e-6, 0.0, options_.max_horizon_s);
    const double tau = options_.accel_tau_s;
    const double ga = tau * (h - tau * (1 - std::exp(-h / tau)));
    const double tv = options_.velocity_tau_s;
    const double gv = tv > 0 ? tv * (1 - std::exp(-h / tv)) : h;
    PoseSample out;
    out.time_us = std::max(time_us, time_us_);
    Eigen::Vector3d dtheta;
    for (int a = 0; a < 3; ++a) {
      out.position[a] = pos_[a].x(0) + gv * pos_[a].x(1) + ga * pos_[a].x(2);
      dtheta[a] = gv * ang_[a].x(1) + ga * ang_[a].x(2);
    }
    out.rotation = (ExpRotation(dtheta) * q_).normalized();
    return out;
  }
  void Reset() override { has_ = false; }
  PredictorModel model() const override { return PredictorModel::kKalman; }

 private:
  PredictorOptions options_;
  bool has_ = false;
  int64_t time_us_ = 0;
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();
  AxisFilter pos_[3], ang_[3];
};

double Percentile95(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t k = static_cast<size_t>(std::ceil(0.95 * static_cast<double>(v.size()))) - 1;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

const char* PredictorModelName(PredictorModel m) {
  switch (m) {
    case PredictorModel::kNone: return "none";
    case PredictorModel::kConstantVelocity: return "cv";
    case PredictorModel::kKalman: return "kalman";
  }
  return "?";
}

StatusOr<PredictorModel> ParsePredictorModel(const std::string& name) {
  for (PredictorModel m : {PredictorModel::kNone, PredictorModel::kConstantVelocity, PredictorModel::kKalman}) {
    if (name == PredictorModelName(m)) return m;
  }
  return InvalidArgument("unknown predictor '" + name + "' (known: none, cv, kalman)");
}

Status PredictorOptions::Check() const {
  const std::pair<double, const char*> positive[] = {
      {window_s, "window_s"},           {position_sigma_m, "position_sigma_m"},
      {angle_sigma_rad, "angle_sigma_rad"}, {position_jerk_psd, "position_jerk_psd"},
      {angle_jerk_psd, "angle_jerk_psd"}, {accel_tau_s, "accel_tau_s"},
      {max_horizon_s, "max_horizon_s"}};
  for (const auto& [v, name] : positive) {
    if (!(v > 0) || !std::isfinite(v)) return InvalidArgument(std::string(name) + " must be > 0, got " + std::to_string(v));
  }
  if (!(velocity_tau_s >= 0) || !std::isfinite(velocity_tau_s)) {
    return InvalidArgument("velocity_tau_s must be >= 0 (0 = off), got " + std::to_string(velocity_tau_s));
  }
  return OkStatus();
}

StatusOr<std::unique_ptr<PosePredictor>> MakePredictor(PredictorModel model, const PredictorOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  switch (model) {
    case PredictorModel::kNone: return std::unique_ptr<PosePredictor>(new NonePredictor());
    case PredictorModel::kConstantVelocity:
      return std::unique_ptr<PosePredictor>(new ConstantVelocityPredictor(options));
    case PredictorModel::kKalman: return std::unique_ptr<PosePredictor>(new KalmanPredictor(options));
  }
  return InvalidArgument("unknown predictor model");
}

StatusOr<PredictionError> EvaluatePredictor(PredictorModel model, const PredictorOptions& options,
                                            const std::vector<PoseSample>& samples,
                                            const std::vector<PoseSample>& truth, double horizon_s,
                                            double warmup_s) {
  if (samples.empty() || truth.empty()) return InvalidArgument("EvaluatePredictor: empty trace");
  if (!(horizon_s >= 0)) return InvalidArgument("horizon_s must be >= 0");
  HOLO_ASSIGN_OR_RETURN(std::unique_ptr<PosePredictor> predictor, MakePredictor(model, options));
  const int64_t horizon_us = std::llround(horizon_s * 1e6);
  const int64_t start_us = samples.front().time_us + std::llround(warmup_s * 1e6);
  std::vector<double> deg, mm;
  for (const PoseSample& s : samples) {
    predictor->Observe(s);
    if (s.time_us < start_us) continue;
    const int64_t target = s.time_us + horizon_us;
    if (target > truth.back().time_us) break;
    const PoseSample p = predictor->Predict(target);
    const PoseSample t = InterpolatePose(truth, target);
    deg.push_back(AngleBetween(p.rotation, t.rotation) / kDeg);
    mm.push_back((p.position - t.position).norm() * 1e3);
  }
  if (deg.empty()) return InvalidArgument("EvaluatePredictor: trace shorter than warm-up + horizon");
  PredictionError e;
  e.count = deg.size();
  double sd = 0, sm = 0;
  for (size_t i = 0; i < deg.size(); ++i) {
    sd += deg[i];
    sm += mm[i];
  }
  e.mean_deg = sd / static_cast<double>(e.count);
  e.mean_mm = sm / static_cast<double>(e.count);
  e.p95_deg = Percentile95(deg);
  e.p95_mm = Percentile95(mm);
  return e;
}

}  // namespace holo::pose
