#include "audio/synthetic_voice.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace holo::audio {
namespace {

constexpr double kPi = std::numbers::pi;
// Vowel formants F1, F2 (Hz): a, e, i, o, u.
constexpr double kVowels[5][2] = {{730, 1090}, {530, 1840}, {300, 2250}, {570, 840}, {320, 920}};

}  // namespace

SyntheticVoice::SyntheticVoice(uint64_t seed, int sample_rate)
    : rate_(sample_rate), rng_(seed * 0x9E3779B97F4A7C15ULL + 0x2545F4914F6CDD1DULL) {}

double SyntheticVoice::Noise() {
  rng_ ^= rng_ >> 12;
  rng_ ^= rng_ << 25;
  rng_ ^= rng_ >> 27;
  const uint64_t v = rng_ * 0x2545F4914F6CDD1DULL;
  return static_cast<double>(v >> 11) * (2.0 / 9007199254740992.0) - 1.0;
}

void SyntheticVoice::Start(Sound sound, int64_t offset) {
  pending_.push_back({position_ + std::max<int64_t>(0, offset), sound});
  std::sort(pending_.begin(), pending_.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
}

float SyntheticVoice::SyllableSample(Syllable& s, int64_t n) {
  const int64_t i = n - s.start;
  if (i >= s.length) {
    s.active = false;
    return 0.0f;
  }
  const double t = static_cast<double>(i) / rate_;
  const double progress = static_cast<double>(i) / static_cast<double>(s.length);
  // Glottal source: one pulse per period, pitch falling over the syllable.
  const double f0 = s.f0 * (1.0 - 0.15 * progress);
  s.phase += f0 / rate_;
  double x = 0.0;
  if (s.phase >= 1.0) {
    s.phase -= 1.0;
    x = 1.0;
  }
  // Two formant resonators in cascade.
  double y = x;
  for (int k = 0; k < 2; ++k) {
    const double out = s.gain[k] * y + s.a1[k] * s.y1[k] + s.a2[k] * s.y2[k];
    s.y2[k] = s.y1[k];
    s.y1[k] = out;
    y = out;
  }
  // Envelope: 4 ms attack, 40 ms release.
  const double attack = std::min(1.0, t / 0.004);
  const double release = std::min(1.0, static_cast<double>(s.length - i) / (0.040 * rate_));
  double v = 6.0 * y * attack * release;
  // Plosive burst at the onset (12 ms, decaying).
  if (t < 0.012) v += 0.25 * Noise() * std::exp(-t / 0.004);
  return static_cast<float>(std::clamp(v, -0.5, 0.5));
}

float SyntheticVoice::KnockSample(const Knock& k, int64_t n) {
  const double t = static_cast<double>(n - k.start) / rate_;
  if (t >= 0.060) {
    knock_.active = false;
    return 0.0f;
  }
  const double tone = 0.35 * std::sin(2.0 * kPi * 180.0 * t) * std::exp(-t / 0.015);
  const double click = 0.3 * Noise() * std::exp(-t / 0.001);
  return static_cast<float>(std::clamp(tone + click, -0.5, 0.5));
}

void SyntheticVoice::Render(std::span<float> out) {
  for (size_t j = 0; j < out.size(); ++j) {
    const int64_t n = position_ + static_cast<int64_t>(j);
    while (!pending_.empty() && pending_.front().first <= n) {
      if (pending_.front().second == Sound::kSyllable) {
        Syllable s;
        s.active = true;
        s.start = n;
        s.length = static_cast<int64_t>((0.14 + 0.12 * (0.5 + 0.5 * Noise())) * rate_);
        s.f0 = 110.0 + 80.0 * (0.5 + 0.5 * Noise());
        const int vowel = std::clamp(static_cast<int>((0.5 + 0.5 * Noise()) * 5.0), 0, 4);
        s.f1 = kVowels[vowel][0];
        s.f2 = kVowels[vowel][1];
        // Two-pole resonators at F1 and F2, bandwidths 90 and 120 Hz.
        const double freqs[2] = {s.f1, s.f2};
        const double bws[2] = {90.0, 120.0};
        for (int k = 0; k < 2; ++k) {
          const double r = std::exp(-kPi * bws[k] / rate_);
          s.gain[k] = 1.0 - r;
          s.a1[k] = 2.0 * r * std::cos(2.0 * kPi * freqs[k] / rate_);
          s.a2[k] = -r * r;
        }
        s.phase = 0.999;  // the first glottal pulse right at the onset
        syllable_ = s;
      } else {
        knock_ = Knock{true, n};
      }
      pending_.erase(pending_.begin());
    }
    float v = 0.0f;
    if (syllable_.active) v += SyllableSample(syllable_, n);
    if (knock_.active) v += KnockSample(knock_, n);
    out[j] = std::clamp(v, -0.5f, 0.5f);
  }
  position_ += static_cast<int64_t>(out.size());
}

}  // namespace holo::audio
