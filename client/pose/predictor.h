// Head-pose predictors: given the tracker samples so far, the pose at a
// later time (the display time = newest sample time + measured latency).
//   none      the newest sample (what a client without prediction shows)
//   cv        constant velocity: a least-squares line through the samples of
//             the last `window_s` (position, and rotation vector relative to
//             the newest orientation), extrapolated; exact on constant linear
//             and angular velocity
//   kalman    a small Kalman filter per axis on position and on orientation
//             (error state: a world-frame rotation vector around the filter's
//             quaternion), state (value, velocity, acceleration) with a
//             damped-acceleration (Singer) model: acceleration decays with
//             time constant `accel_tau_s`, so long horizons do not run away
// Predictors take samples in time order; a sample not after the previous is
// ignored. Times are the samples' (injected) clock, never the wall clock.
#pragma once

#include <array>
#include <deque>
#include <memory>
#include <string>

#include "client/pose/head_pose.h"
#include "common/status.h"

namespace holo::pose {

enum class PredictorModel { kNone, kConstantVelocity, kKalman };
const char* PredictorModelName(PredictorModel m);  // "none", "cv", "kalman"
StatusOr<PredictorModel> ParsePredictorModel(const std::string& name);

struct PredictorOptions {
  // cv: regression window, seconds (at least the two newest samples are used).
  double window_s = 0.035;
  // kalman: measurement noise σ (position m, angle rad) and the white-jerk
  // spectral densities of the process (m²/s⁵, rad²/s⁵), acceleration decay.
  double position_sigma_m = 0.0005;
  double angle_sigma_rad = 0.0010;
  double position_jerk_psd = 40.0;
  double angle_jerk_psd = 400.0;
  double accel_tau_s = 0.05;
  // kalman: velocity decays with this time constant over the prediction
  // horizon only (0 = off): head turns end; a pure constant-velocity
  // extrapolation overshoots at their end.
  double velocity_tau_s = 0.0;
  // Predictions further ahead than this are clamped (seconds).
  double max_horizon_s = 0.5;
  Status Check() const;
};

class PosePredictor {
 public:
  virtual ~PosePredictor() = default;
  // Adds a tracker sample. Returns false (ignoring it) if not after the previous one.
  virtual bool Observe(const PoseSample& sample) = 0;
  // The predicted pose at `time_us` (≥ the newest sample's time; earlier
  // times give the newest estimate). HOLO_CHECKs that a sample was observed.
  virtual PoseSample Predict(int64_t time_us) const = 0;
  virtual void Reset() = 0;
  virtual PredictorModel model() const = 0;
};

// InvalidArgument if `options` fail Check.
StatusOr<std::unique_ptr<PosePredictor>> MakePredictor(PredictorModel model, const PredictorOptions& options = {});

// Prediction error of `model` over a trace: for every sample i after a
// warm-up of `warmup_s`, the predictor has seen samples 0..i and predicts
// time t_i + horizon; the truth is `truth` interpolated there (pass the
// trace itself for recorded data). Samples whose target is past the end are
// skipped.
struct PredictionError {
  double mean_deg = 0, p95_deg = 0;
  double mean_mm = 0, p95_mm = 0;
  size_t count = 0;
};
StatusOr<PredictionError> EvaluatePredictor(PredictorModel model, const PredictorOptions& options,
                                            const std::vector<PoseSample>& samples,
                                            const std::vector<PoseSample>& truth, double horizon_s,
                                            double warmup_s = 0.5);

}  // namespace holo::pose
