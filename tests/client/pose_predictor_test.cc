// Head-pose predictors: exactness and ranking on controlled motions. No timing.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "client/pose/head_motion.h"
#include "client/pose/predictor.h"

namespace holo::pose {
namespace {

constexpr double kDeg = M_PI / 180.0;

// Samples at `rate_hz` for `seconds` of a motion given as position and
// rotation vector (world frame) functions of time.
template <typename PositionFn, typename RotvecFn>
std::vector<PoseSample> Sample(PositionFn position, RotvecFn rotvec, double rate_hz, double seconds) {
  std::vector<PoseSample> out;
  for (int i = 0; i <= static_cast<int>(seconds * rate_hz); ++i) {
    PoseSample s;
    s.time_us = std::llround(i / rate_hz * 1e6);
    const double t = s.time_us * 1e-6;  // the motion at the sample's own (rounded) time
    s.position = position(t);
    s.rotation = ExpRotation(rotvec(t)) * RotationFromYawPitchRoll(0.2, 0.1, 0.0);
    out.push_back(s);
  }
  return out;
}

PredictionError Eval(PredictorModel m, const std::vector<PoseSample>& s, double horizon_s) {
  auto e = EvaluatePredictor(m, PredictorOptions{}, s, s, horizon_s, 0.3);
  HOLO_CHECK(e.ok());
  return *e;
}

TEST(Predictor, ConstantVelocityIsExactOnLinearMotion) {
  const Eigen::Vector3d v(0.4, -0.2, 0.05), w(0.3, 1.2, -0.4);  // m/s, rad/s about a fixed axis
  const auto s = Sample([&](double t) { return Eigen::Vector3d(1 + v.x() * t, 2 + v.y() * t, 1.6 + v.z() * t); },
                        [&](double t) { return Eigen::Vector3d(w.x() * t, w.y() * t, w.z() * t); }, 90.0, 2.0);
  for (double h : {0.02, 0.05, 0.1}) {
    const PredictionError cv = Eval(PredictorModel::kConstantVelocity, s, h);
    EXPECT_LT(cv.mean_mm, 1e-6) << h;
    EXPECT_LT(cv.mean_deg, 1e-6) << h;
    const PredictionError none = Eval(PredictorModel::kNone, s, h);
    EXPECT_NEAR(none.mean_mm, v.norm() * h * 1e3, 1e-6);
    EXPECT_NEAR(none.mean_deg, w.norm() * h / kDeg, 1e-6);
  }
}

TEST(Predictor, KalmanBeatsConstantVelocityOnSmoothAcceleratingMotion) {
  // Smooth head oscillation: yaw ±40° at 0.4 Hz, the eye swinging ±15 cm.
  const auto s = Sample([](double t) { return Eigen::Vector3d(0.15 * std::sin(2 * M_PI * 0.4 * t), 0, 1.6); },
                        [](double t) { return Eigen::Vector3d(0, 0, 40 * kDeg * std::sin(2 * M_PI * 0.4 * t)); },
                        90.0, 6.0);
  for (double h : {0.05, 0.1}) {
    const PredictionError none = Eval(PredictorModel::kNone, s, h);
    const PredictionError cv = Eval(PredictorModel::kConstantVelocity, s, h);
    const PredictionError kf = Eval(PredictorModel::kKalman, s, h);
    EXPECT_LT(cv.mean_deg, 0.5 * none.mean_deg) << h;
    EXPECT_LT(kf.mean_deg, 0.8 * cv.mean_deg) << h;
    EXPECT_LT(kf.mean_mm, 0.8 * cv.mean_mm) << h;
  }
}

TEST(Predictor, PredictionBeatsNoneOnTheSyntheticGenerator) {
  HeadMotionOptions o;
  o.duration_s = 20;
  auto s = GenerateHeadMotion(o);
  ASSERT_TRUE(s.ok());
  auto e = [&](PredictorModel m) {
    auto r = EvaluatePredictor(m, PredictorOptions{}, *s, *s, 0.05);
    HOLO_CHECK(r.ok());
    return *r;
  };
  EXPECT_LT(e(PredictorModel::kConstantVelocity).mean_deg, 0.7 * e(PredictorModel::kNone).mean_deg);
  EXPECT_LT(e(PredictorModel::kKalman).p95_deg, e(PredictorModel::kConstantVelocity).p95_deg);
}

TEST(Predictor, IgnoresStaleSamplesAndValidatesOptions) {
  for (PredictorModel m : {PredictorModel::kNone, PredictorModel::kConstantVelocity, PredictorModel::kKalman}) {
    auto p = MakePredictor(m);
    ASSERT_TRUE(p.ok());
    PoseSample s;
    s.time_us = 1000;
    EXPECT_TRUE((*p)->Observe(s));
    s.time_us = 1000;
    s.position.x() = 5;
    EXPECT_FALSE((*p)->Observe(s));
    EXPECT_LT((*p)->Predict(50000).position.norm(), 1e-9) << PredictorModelName(m);
    EXPECT_EQ(ParsePredictorModel(PredictorModelName(m)).value(), m);
  }
  EXPECT_FALSE(ParsePredictorModel("magic").ok());
  PredictorOptions bad;
  bad.accel_tau_s = -1;
  EXPECT_FALSE(MakePredictor(PredictorModel::kKalman, bad).ok());
}

}  // namespace
}  // namespace holo::pose
