#include "audio/sofa_hrtf.h"

#include <gtest/gtest.h>
#include <mysofa.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>

#include "audio/ear_measure.h"
#include "audio/spatializer.h"
#include "test_util.h"

namespace holo::audio {
namespace {

// The MIT KEMAR set ships with Debian's libmysofa1 (a dependency of
// libmysofa-dev, installed by scripts/setup.sh): not a file of this repository.
constexpr const char* kKemar = "/usr/share/libmysofa/MIT_KEMAR_normal_pinna.sofa";

std::string ReadAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

std::string WriteTemp(const std::string& name, const std::string& bytes) {
  const std::string p = (std::filesystem::temp_directory_path() / name).string();
  std::ofstream(p, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return p;
}

class SofaTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(std::filesystem::exists(kKemar)) << kKemar << " missing: install libmysofa1 (scripts/setup.sh)";
  }
};

TEST_F(SofaTest, OpensKemarAndInterpolates) {
  auto h = SofaHrtf::Open(kKemar, 48000);
  ASSERT_TRUE(h.ok()) << h.status().ToString();
  EXPECT_EQ((*h)->measurements(), 710);
  EXPECT_GT((*h)->filter_length(), 500);
  std::vector<float> l, r, l2, r2;
  // On the right: the right ear gets more energy.
  (*h)->Filter({0, -1, 0}, &l, &r);
  double el = 0, er = 0;
  for (size_t i = 0; i < l.size(); ++i) {
    el += l[i] * l[i];
    er += r[i] * r[i];
  }
  EXPECT_GT(10 * std::log10(er / el), 6.0);
  // Between two measured azimuths (KEMAR has 5° steps at 0° elevation) the
  // filter differs from both neighbours: interpolation, not nearest neighbour.
  auto dir = [](double az) {
    const double a = -az * std::numbers::pi / 180;
    return Eigen::Vector3f(static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a)), 0.0f);
  };
  (*h)->Filter(dir(30), &l, &r);
  (*h)->Filter(dir(32.5), &l2, &r2);
  std::vector<float> l3, r3;
  (*h)->Filter(dir(35), &l3, &r3);
  double d1 = 0, d2 = 0;
  for (size_t i = 0; i < l.size(); ++i) {
    d1 += (l2[i] - l[i]) * (l2[i] - l[i]);
    d2 += (l2[i] - l3[i]) * (l2[i] - l3[i]);
  }
  EXPECT_GT(d1, 0.0);
  EXPECT_GT(d2, 0.0);
}

TEST_F(SofaTest, RefusesWrongLayoutWithReason) {
  const std::string bytes = ReadAll(kKemar);
  // A file with another convention: the same HDF5 bytes with the convention
  // name changed (same length) to a transfer-function set.
  std::string tf = bytes;
  size_t at = 0;
  int patched = 0;
  while ((at = tf.find("SimpleFreeFieldHRIR", at)) != std::string::npos) {
    tf.replace(at, 19, "SimpleFreeFieldHRTF");
    ++patched;
  }
  ASSERT_GT(patched, 0);
  auto r = SofaHrtf::Open(WriteTemp("holo_sofa_tf.sofa", tf), 48000);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("SimpleFreeFieldHRIR"), std::string::npos) << r.status().ToString();

  // One ear only, and a Data.IR that does not match M × R × N: the layout
  // check names the rule (checked on the parsed structure).
  int err = 0;
  MYSOFA_HRTF* h = mysofa_load_data(bytes.data(), bytes.size(), &err);
  ASSERT_NE(h, nullptr);
  EXPECT_TRUE(CheckSofaLayout(*h).ok());
  h->R = 1;
  Status s = CheckSofaLayout(*h);
  EXPECT_NE(s.message().find("1 receiver(s), need 2"), std::string::npos) << s.ToString();
  h->R = 2;
  h->N = 256;
  s = CheckSofaLayout(*h);
  EXPECT_NE(s.message().find("Data.IR has"), std::string::npos) << s.ToString();
  h->N = 512;
  h->DataIR.values[7] = std::nanf("");
  s = CheckSofaLayout(*h);
  EXPECT_NE(s.message().find("not finite"), std::string::npos) << s.ToString();
  mysofa_free(h);

  // Not a SOFA file at all, and a missing one.
  auto wav = SofaHrtf::Open(test::TestDataPath("audio/speech_48k.wav"), 48000);
  ASSERT_FALSE(wav.ok());
  EXPECT_NE(wav.status().message().find("not a SOFA"), std::string::npos) << wav.status().ToString();
  EXPECT_EQ(SofaHrtf::Open("/nonexistent/x.sofa", 48000).status().code(), StatusCode::kNotFound);
}

// Truncated files are refused, never crash (libmysofa parses untrusted bytes).
TEST_F(SofaTest, RefusesTruncatedFiles) {
  const std::string bytes = ReadAll(kKemar);
  for (size_t len : {size_t{0}, size_t{8}, size_t{100}, size_t{4096}, bytes.size() / 3, bytes.size() / 2,
                     bytes.size() - 1000}) {
    auto r = SofaHrtf::Open(WriteTemp("holo_sofa_cut.sofa", bytes.substr(0, len)), 48000);
    EXPECT_FALSE(r.ok()) << len;
  }
}

// Flipped bits anywhere (header, attributes, data) are refused or accepted
// with sane filters, never a crash or a hang (FuzzSofa).
TEST_F(SofaTest, BitFlipsNeverCrash) {
  const std::string bytes = ReadAll(kKemar);
  std::mt19937 rng(11);
  std::uniform_int_distribution<size_t> pos(0, bytes.size() - 1);
  // Fails by crashing, or through FuzzSofa's check on an accepted file's filters.
  for (int i = 0; i < 12; ++i) {
    std::string b = bytes;
    const size_t at = i < 4 ? static_cast<size_t>(i) * 97 : pos(rng);  // the first flips hit the HDF5 superblock
    b[at] = static_cast<char>(b[at] ^ (1 << (i % 8)));
    (void)FuzzSofa(reinterpret_cast<const uint8_t*>(b.data()), b.size());
  }
}

// The SOFA path of the spatializer reproduces the file's own interaural cues
// within 10 % (ITD) and 10 % or 0.5 dB (ILD).
TEST_F(SofaTest, SpatializerMatchesFileCues) {
  SpatializerOptions o;
  o.sofa_path = kKemar;
  auto sp = Spatializer::Create(o);
  ASSERT_TRUE(sp.ok()) << sp.status().ToString();
  EXPECT_NE((*sp)->hrtf_status().find("sofa: "), std::string::npos);
  (*sp)->SetListener({0, 0, 1.6f, 0, 0, 0});
  auto id = (*sp)->AddSpeaker();
  ASSERT_TRUE(id.ok());
  std::mt19937 rng(1);
  std::normal_distribution<float> noise(0.0f, 0.1f);
  std::vector<float> x(24960);
  for (int az : {-90, -60, -30, 30, 60, 90}) {
    const float a = -static_cast<float>(az) * std::numbers::pi_v<float> / 180.0f;
    SpeakerPlacement s;
    s.position = {std::cos(a), std::sin(a), 1.6f};
    s.facing = -s.position + Eigen::Vector3f(0, 0, 1.6f);
    ASSERT_TRUE((*sp)->SetSpeaker(*id, s).ok());
    for (float& v : x) v = noise(rng);
    ASSERT_TRUE((*sp)->Push(*id, x).ok());
    // The first block crossfades from the previous direction; measure after it.
    (void)(*sp)->Render(960);
    const auto y = (*sp)->Render(24000);
    const EarMeasurement m = MeasureEars(y, 2400, 21600, 48000, 72);
    auto file = SofaFileCues(kKemar, az);
    ASSERT_TRUE(file.ok());
    std::printf("azimuth %d: ITD %.3f ms (file %.3f), ILD %.2f dB (file %.2f)\n", az, m.itd_ms, file->itd_ms, m.ild_db,
                file->ild_db);
    EXPECT_NEAR(m.itd_ms, file->itd_ms, 0.1 * std::abs(file->itd_ms)) << az;
    EXPECT_NEAR(m.ild_db, file->ild_db, std::max(0.5, 0.1 * std::abs(file->ild_db))) << az;
  }
}

// A fast head turn (180° in 0.25 s, 14.4° per 20 ms block) on a 500 Hz tone:
// with the crossfade the largest second difference of the ear signals stays
// within 1.5× of the largest a still source has at any of the directions
// passed (no click); switching filters without the crossfade exceeds 3×
// (the measure sees clicks).
TEST_F(SofaTest, FastHeadTurnHasNoDiscontinuity) {
  auto h = SofaHrtf::Open(kKemar, 48000);
  ASSERT_TRUE(h.ok());
  const int block = 960, blocks = 40;
  auto tone = [](int i) { return 0.5f * std::sin(2 * std::numbers::pi_v<float> * 500.0f * static_cast<float>(i) / 48000.0f); };
  auto dir_at = [](int b) {
    const float az = std::min(180.0f, 14.4f * static_cast<float>(std::max(0, b - 10)));  // turns from block 10
    const float a = -az * std::numbers::pi_v<float> / 180.0f;
    return Eigen::Vector3f(std::cos(a), std::sin(a), 0.0f);
  };
  auto max_d2 = [](const std::vector<float>& y, size_t from) {
    double m = 0;
    for (size_t ch = 0; ch < 2; ++ch)
      for (size_t i = from + 2; i < y.size() / 2; ++i)
        m = std::max(m, static_cast<double>(std::abs(y[2 * i + ch] - 2 * y[2 * (i - 1) + ch] + y[2 * (i - 2) + ch])));
    return m;
  };
  auto render = [&](bool crossfade, bool still_at_block, int still_block) {
    HrtfConvolver c(**h);
    std::vector<float> out(static_cast<size_t>(2 * block * blocks), 0.0f);
    std::vector<float> x(block);
    for (int b = 0; b < blocks; ++b) {
      for (int i = 0; i < block; ++i) x[static_cast<size_t>(i)] = tone(b * block + i);
      c.Process(x, dir_at(still_at_block ? still_block : b), 1.0f,
                std::span<float>(out).subspan(static_cast<size_t>(2 * block * b), static_cast<size_t>(2 * block)),
                crossfade);
    }
    return out;
  };
  double still = 0;
  for (int b = 10; b <= 23; ++b) still = std::max(still, max_d2(render(true, true, b), 5 * block));
  const double smooth = max_d2(render(true, false, 0), 5 * block);
  const double hard = max_d2(render(false, false, 0), 5 * block);
  std::printf("max |second difference|: still %.5f, turning with crossfade %.5f, hard switch %.5f\n", still, smooth, hard);
  EXPECT_LE(smooth, 1.5 * still) << "crossfaded " << smooth << " still " << still;
  EXPECT_GE(hard, 3.0 * still) << "hard switch " << hard << " still " << still;
}

}  // namespace
}  // namespace holo::audio
