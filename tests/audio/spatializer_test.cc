#include "audio/ear_measure.h"
#include "audio/spatializer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "audio/voice_codec.h"

namespace holo::audio {
namespace {

constexpr float kDeg = std::numbers::pi_v<float> / 180.0f;

struct Ears {
  double ild_db = 0;   // right − left level
  double itd_ms = 0;   // > 0: the left ear lags (source on the right)
  double level_db = 0; // both ears
};

// White noise from a source at `azimuth_deg` (+ right) and 1 m, rendered
// through the loopback device; the speaker faces `facing`.
Ears Measure(float azimuth_deg, float facing_yaw_offset_deg = 180.0f, float distance = 1.0f) {
  auto sp = Spatializer::Create({});
  EXPECT_TRUE(sp.ok()) << sp.status().ToString();
  if (!sp.ok()) return {};
  protocol::HeadPose listener{0, 0, 1.6f, 0, 0, 0};
  (*sp)->SetListener(listener);
  auto id = (*sp)->AddSpeaker();
  EXPECT_TRUE(id.ok());
  const float a = -azimuth_deg * kDeg;  // room yaw is + to the left
  SpeakerPlacement s;
  s.position = Eigen::Vector3f(distance * std::cos(a), distance * std::sin(a), 1.6f);
  const float face = a + facing_yaw_offset_deg * kDeg;  // 180°: towards the listener
  s.facing = Eigen::Vector3f(std::cos(face), std::sin(face), 0.0f);
  EXPECT_TRUE((*sp)->SetSpeaker(*id, s).ok());
  std::mt19937 rng(1);
  std::normal_distribution<float> noise(0.0f, 0.1f);
  std::vector<float> x(kSampleRate / 2);
  for (float& v : x) v = noise(rng);
  EXPECT_TRUE((*sp)->Push(*id, x).ok());
  const std::vector<float> y = (*sp)->Render(kSampleRate / 2);
  // Skip the onset (HRTF filters fade in); lag search within ±1.5 ms.
  const EarMeasurement m = MeasureEars(y, 2400, x.size() - 2400, kSampleRate, 72);
  Ears e;
  e.ild_db = m.ild_db;
  e.itd_ms = m.itd_ms;
  e.level_db = m.level_db;
  return e;
}

TEST(Spatializer, HrtfIsEnabledOnTheLoopbackDevice) {
  auto sp = Spatializer::Create({});
  ASSERT_TRUE(sp.ok()) << sp.status().ToString();
  EXPECT_EQ((*sp)->hrtf_status().rfind("enabled", 0), 0u) << (*sp)->hrtf_status();
}

TEST(Spatializer, DirectionGivesInterauralLevelAndTimeDifferences) {
  const Ears right = Measure(90), left = Measure(-90), front = Measure(0);
  std::printf("+90: ILD %.1f dB ITD %.3f ms; -90: ILD %.1f dB ITD %.3f ms; 0: ILD %.2f dB ITD %.3f ms\n",
              right.ild_db, right.itd_ms, left.ild_db, left.itd_ms, front.ild_db, front.itd_ms);
  EXPECT_GT(right.ild_db, 6.0);
  EXPECT_GE(right.itd_ms, 0.55);
  EXPECT_LE(right.itd_ms, 0.75);
  EXPECT_LT(left.ild_db, -6.0);
  EXPECT_LE(left.itd_ms, -0.55);
  EXPECT_GE(left.itd_ms, -0.75);
  EXPECT_NEAR(right.ild_db, -left.ild_db, 1.0);
  EXPECT_NEAR(front.ild_db, 0.0, 1.0);
  EXPECT_NEAR(front.itd_ms, 0.0, 0.05);
}

TEST(Spatializer, FacingAwayIsQuieter) {
  const Ears facing = Measure(30, 180), away = Measure(30, 0), side = Measure(30, 90);
  std::printf("facing %.1f dB, side %.1f dB, away %.1f dB\n", facing.level_db, side.level_db, away.level_db);
  EXPECT_GE(facing.level_db - away.level_db, 6.0);
  EXPECT_GT(facing.level_db, side.level_db);
  EXPECT_GT(side.level_db, away.level_db);
}

TEST(Spatializer, DistanceAttenuates) {
  const Ears near = Measure(0, 180, 1.0f), far = Measure(0, 180, 2.0f);
  EXPECT_NEAR(near.level_db - far.level_db, 6.0, 1.0);
}

TEST(Spatializer, CardioidGain) {
  SpatializerOptions o;
  o.directivity_floor = 0.0f;
  SpeakerPlacement s;  // at origin facing +x
  EXPECT_NEAR(DirectivityGain(o, s, {1, 0, 0}), 1.0f, 1e-6);
  EXPECT_NEAR(DirectivityGain(o, s, {0, 1, 0}), 0.5f, 1e-6);
  EXPECT_NEAR(DirectivityGain(o, s, {-1, 0, 0}), 0.0f, 1e-6);
  EXPECT_NEAR(DirectivityGain(o, s, {1, 1, 0}), 0.5f * (1 + std::sqrt(0.5f)), 1e-5);
  EXPECT_FALSE(SpatializerOptions{.ref_distance_m = 0}.Check().ok());
}

}  // namespace
}  // namespace holo::audio
