#include "audio/synthetic_voice.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace holo::audio {
namespace {

// First sample at or after `from` whose magnitude exceeds `threshold`; -1 if none.
int64_t FirstAbove(const std::vector<float>& x, int64_t from, float threshold) {
  for (size_t i = static_cast<size_t>(from); i < x.size(); ++i)
    if (std::abs(x[i]) > threshold) return static_cast<int64_t>(i);
  return -1;
}

std::vector<float> RenderInFrames(SyntheticVoice& v, size_t n) {
  std::vector<float> out(n);
  for (size_t i = 0; i < n; i += 960) v.Render(std::span<float>(out).subspan(i, std::min<size_t>(960, n - i)));
  return out;
}

TEST(SyntheticVoice, SoundsStartWhereTheyAreScheduledAndAreSilentBetween) {
  SyntheticVoice v(5);
  v.Start(SyntheticVoice::Sound::kSyllable, 4800);    // 100 ms
  v.Start(SyntheticVoice::Sound::kKnock, 4 * 4800);   // 400 ms, after the syllable (≤ 260 ms long)
  v.Start(SyntheticVoice::Sound::kSyllable, 50000);   // carried over to a later 20 ms call
  const std::vector<float> x = RenderInFrames(v, 72000);
  EXPECT_EQ(FirstAbove(x, 0, 1e-4f), 4800);           // nothing before the onset
  EXPECT_LE(FirstAbove(x, 4800 + 12480, 0.05f), 19205) << "silence between the syllable and the knock";
  EXPECT_GE(FirstAbove(x, 4800 + 12480, 0.05f), 19200);
  EXPECT_GE(FirstAbove(x, 19200 + 2880, 0.05f), 50000);
  EXPECT_LE(FirstAbove(x, 19200 + 2880, 0.05f), 50005);
  double energy = 0, peak = 0;
  for (int i = 4800; i < 4800 + 6720; ++i) {  // the first 140 ms of the syllable
    energy += x[i] * x[i];
    peak = std::max(peak, static_cast<double>(std::abs(x[i])));
  }
  EXPECT_GT(std::sqrt(energy / 6720), 0.03) << "audible";
  EXPECT_LE(peak, 0.5);
}

TEST(SyntheticVoice, SameEventsSameSamples) {
  SyntheticVoice a(9), b(9), c(10);
  for (SyntheticVoice* v : {&a, &b, &c}) {
    v->Start(SyntheticVoice::Sound::kSyllable, 100);
    v->Start(SyntheticVoice::Sound::kSyllable, 20000);
  }
  const auto xa = RenderInFrames(a, 40000), xb = RenderInFrames(b, 40000), xc = RenderInFrames(c, 40000);
  EXPECT_EQ(xa, xb);
  EXPECT_NE(xa, xc);  // another seed: other pitch and vowels
}

}  // namespace
}  // namespace holo::audio
