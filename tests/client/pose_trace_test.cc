// Head poses, recorded traces (CSV) and the synthetic head-motion generator.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "client/pose/head_motion.h"
#include "client/pose/head_pose.h"
#include "client/pose/trace.h"
#include "test_util.h"

namespace holo::pose {
namespace {

constexpr double kDeg = M_PI / 180.0;

Eigen::Vector3d Forward(const Eigen::Quaterniond& q) { return q * Eigen::Vector3d::UnitZ(); }
Eigen::Vector3d Right(const Eigen::Quaterniond& q) { return q * Eigen::Vector3d::UnitX(); }

TEST(HeadPose, EulerConvention) {
  EXPECT_LT((Forward(RotationFromYawPitchRoll(0, 0, 0)) - Eigen::Vector3d::UnitX()).norm(), 1e-12);
  EXPECT_LT((Right(RotationFromYawPitchRoll(0, 0, 0)) + Eigen::Vector3d::UnitY()).norm(), 1e-12);
  // Yaw +90°: turned left, looking along +y.
  EXPECT_LT((Forward(RotationFromYawPitchRoll(90 * kDeg, 0, 0)) - Eigen::Vector3d::UnitY()).norm(), 1e-12);
  // Pitch up: the line of sight rises.
  EXPECT_NEAR(Forward(RotationFromYawPitchRoll(0, 30 * kDeg, 0)).z(), std::sin(30 * kDeg), 1e-12);
  // Roll positive: right ear down, so the camera's x axis points down a bit.
  EXPECT_LT(Right(RotationFromYawPitchRoll(0, 0, 10 * kDeg)).z(), -0.1);
}

TEST(HeadPose, EulerRoundTrip) {
  for (double yaw : {-170.0, -45.0, 0.0, 30.0, 179.0}) {
    for (double pitch : {-80.0, -10.0, 0.0, 25.0, 89.0}) {
      for (double roll : {-30.0, 0.0, 12.0}) {
        const Eigen::Vector3d ypr = YawPitchRollFromRotation(RotationFromYawPitchRoll(yaw * kDeg, pitch * kDeg, roll * kDeg));
        EXPECT_NEAR(ypr.x() / kDeg, yaw, 1e-6);
        EXPECT_NEAR(ypr.y() / kDeg, pitch, 1e-6);
        EXPECT_NEAR(ypr.z() / kDeg, roll, 1e-6);
      }
    }
  }
}

TEST(HeadPose, LogExpAndInterpolation) {
  const Eigen::Vector3d r(0.3, -0.2, 1.1);
  EXPECT_LT((LogRotation(ExpRotation(r)) - r).norm(), 1e-12);
  PoseSample a, b;
  a.time_us = 0;
  b.time_us = 1000;
  b.position = Eigen::Vector3d(1, 2, 3);
  b.rotation = ExpRotation(Eigen::Vector3d(0, 0, 0.5));
  const PoseSample m = InterpolatePose({a, b}, 250);
  EXPECT_LT((m.position - Eigen::Vector3d(0.25, 0.5, 0.75)).norm(), 1e-12);
  EXPECT_NEAR(AngleBetween(m.rotation, a.rotation), 0.125, 1e-9);
  EXPECT_EQ(InterpolatePose({a, b}, 5000).position, b.position);
}

TEST(PoseFeed, RejectsOutOfOrderAndBadSamples) {
  PoseFeed feed;
  feed.set_capacity(3);
  PoseSample s;
  for (int i = 0; i < 5; ++i) {
    s.time_us = i * 1000;
    EXPECT_TRUE(feed.Push(s));
  }
  EXPECT_EQ(feed.samples().size(), 3u);
  EXPECT_EQ(feed.newest().time_us, 4000);
  s.time_us = 4000;
  EXPECT_FALSE(feed.Push(s));
  s.time_us = 5000;
  s.position.x() = std::nan("");
  EXPECT_FALSE(feed.Push(s));
}

TEST(HeadTrace, ReadsTheSampleTrace) {
  auto trace = ReadHeadTrace(test::TestDataPath("head/lookaround_72hz.csv"));
  ASSERT_TRUE(trace.ok()) << trace.status().ToString();
  EXPECT_GT(trace->size(), 3000u);
  for (size_t i = 1; i < trace->size(); ++i) ASSERT_GT((*trace)[i].time_us, (*trace)[i - 1].time_us);
  // Standing eye height.
  EXPECT_NEAR(trace->front().position.z(), 1.68, 0.05);
}

TEST(HeadTrace, FormatParseRoundTrip) {
  HeadMotionOptions o;
  o.duration_s = 2;
  auto samples = GenerateHeadMotion(o);
  ASSERT_TRUE(samples.ok());
  auto parsed = ParseHeadTrace(FormatHeadTrace(*samples, {"a comment"}), "mem");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  ASSERT_EQ(parsed->size(), samples->size());
  for (size_t i = 0; i < samples->size(); ++i) {
    EXPECT_EQ((*parsed)[i].time_us, (*samples)[i].time_us);
    EXPECT_LT(((*parsed)[i].position - (*samples)[i].position).norm(), 1e-5);
    EXPECT_LT(AngleBetween((*parsed)[i].rotation, (*samples)[i].rotation), 1e-5);
  }
}

std::string ErrorOf(const std::string& text) {
  auto r = ParseHeadTrace(text, "t.csv");
  return r.ok() ? "OK" : r.status().message();
}

TEST(HeadTrace, ErrorsNameLineAndField) {
  const std::string header = "time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg\n";
  const std::string good = "0.0,0,0,1.6,0,0,0\n";
  EXPECT_EQ(ErrorOf(header + good), "OK");
  EXPECT_EQ(ErrorOf(good), "OK");  // header optional
  EXPECT_EQ(ErrorOf("# only a comment\n\n" + header + "# x\n" + good + "\n"), "OK");
  EXPECT_EQ(ErrorOf(header + "0.0,0,0,1.6,0,0,0\r\n0.01,0,0,1.6,1,0,0\r\n"), "OK");

  std::string e = ErrorOf(header + good + "0.01,0,0,1.6,0,0\n");
  EXPECT_NE(e.find("t.csv:3:"), std::string::npos) << e;
  EXPECT_NE(e.find("expected 7 fields"), std::string::npos) << e;
  EXPECT_NE(e.find("got 6"), std::string::npos) << e;

  e = ErrorOf(header + good + "0.01,0,0,1.6,abc,0,0\n");
  EXPECT_NE(e.find("t.csv:3: field 5 (yaw_deg): 'abc' is not a finite number"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.01,0,0,1.6,0,nan,0\n");
  EXPECT_NE(e.find("field 6 (pitch_deg)"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.01,0,inf,1.6,0,0,0\n");
  EXPECT_NE(e.find("field 3 (y_m)"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.01,0,0,1.6,0,0,\n");
  EXPECT_NE(e.find("field 7 (roll_deg): '' is not a finite number"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.01,0,0,1.6 x,0,0,0\n");
  EXPECT_NE(e.find("field 4 (z_m)"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.01,0,0,1.6,0,95,0\n");
  EXPECT_NE(e.find("t.csv:3: field 6 (pitch_deg): 95 is out of range"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.01,5000,0,1.6,0,0,0\n");
  EXPECT_NE(e.find("field 2 (x_m)"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.0,0,0,1.6,0,0,0\n");
  EXPECT_NE(e.find("t.csv:3: field 1 (time_s): 0.0 is not after the previous sample"), std::string::npos) << e;
  e = ErrorOf(header + good + "0.01,0,0,1.6,0,0,0,7\n");
  EXPECT_NE(e.find("got 8"), std::string::npos) << e;
  e = ErrorOf(header);
  EXPECT_NE(e.find("no pose samples"), std::string::npos) << e;
  e = ErrorOf("");
  EXPECT_NE(e.find("no pose samples"), std::string::npos) << e;
  // A second non-numeric line is an error, not another header.
  e = ErrorOf(header + header);
  EXPECT_NE(e.find("t.csv:2: field 1 (time_s)"), std::string::npos) << e;
  TraceLimits small;
  small.max_samples = 1;
  auto r = ParseHeadTrace(header + good + "0.01,0,0,1.6,0,0,0\n", "t.csv", small);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("more than 1 samples"), std::string::npos);
}

TEST(HeadTrace, EveryPrefixParsesOrFailsCleanly) {
  HeadMotionOptions o;
  o.duration_s = 0.1;
  auto samples = GenerateHeadMotion(o);
  ASSERT_TRUE(samples.ok());
  const std::string text = FormatHeadTrace(*samples);
  for (size_t n = 0; n <= text.size(); ++n) {
    const std::string prefix = text.substr(0, n);  // fresh buffer per prefix
    auto r = ParseHeadTrace(prefix, "p");
    if (r.ok()) {
      EXPECT_LE(r->size(), samples->size());
    }
  }
}

TEST(HeadTrace, MissingFile) {
  auto r = ReadHeadTrace("/nonexistent/head.csv");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
}

TEST(HeadMotion, DeterministicAndPlausible) {
  for (HeadMotionKind kind : {HeadMotionKind::kLookAround, HeadMotionKind::kWalk}) {
    HeadMotionOptions o;
    o.kind = kind;
    o.duration_s = 20;
    std::vector<PoseSample> truth;
    auto a = GenerateHeadMotion(o, &truth);
    auto b = GenerateHeadMotion(o);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_EQ(a->size(), static_cast<size_t>(20 * 90 + 1));
    ASSERT_EQ(truth.size(), a->size());
    double max_speed_deg = 0, total_turn_deg = 0, max_height_dev = 0, path_m = 0;
    for (size_t i = 0; i < a->size(); ++i) {
      ASSERT_EQ((*a)[i].position, (*b)[i].position);
      if (i == 0) continue;
      const double dt = (truth[i].time_us - truth[i - 1].time_us) * 1e-6;
      const double turn = AngleBetween(truth[i].rotation, truth[i - 1].rotation) / kDeg;
      max_speed_deg = std::max(max_speed_deg, turn / dt);
      total_turn_deg += turn;
      path_m += (truth[i].position - truth[i - 1].position).norm();
      max_height_dev = std::max(max_height_dev, std::abs(truth[i].position.z() - o.stand_position.z()));
    }
    // Heads turn at up to a few hundred °/s, and keep turning.
    EXPECT_LT(max_speed_deg, 400.0);
    EXPECT_GT(max_speed_deg, 60.0);
    EXPECT_GT(total_turn_deg, 200.0);
    EXPECT_LT(max_height_dev, 0.1);
    if (kind == HeadMotionKind::kWalk) {
      EXPECT_GT(path_m, 5.0);
    } else {
      EXPECT_LT(path_m, 5.0);
    }
  }
  HeadMotionOptions bad;
  bad.rate_hz = 0;
  EXPECT_FALSE(GenerateHeadMotion(bad).ok());
}

}  // namespace
}  // namespace holo::pose
