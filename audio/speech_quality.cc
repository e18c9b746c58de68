#include "audio/speech_quality.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <vector>

namespace holo::audio {
namespace {

constexpr double kMinDb = -10.0, kMaxDb = 35.0;
constexpr double kSpeechRangeDb = 40.0;

// In-place radix-2 FFT; x.size() must be a power of two.
void Fft(std::vector<std::complex<double>>& x) {
  const size_t n = x.size();
  for (size_t i = 1, j = 0; i < n; ++i) {
    size_t bit = n >> 1;
    for (; j & bit; bit >>= 1) j ^= bit;
    j ^= bit;
    if (i < j) std::swap(x[i], x[j]);
  }
  for (size_t len = 2; len <= n; len <<= 1) {
    const double a = -2 * std::numbers::pi / static_cast<double>(len);
    const std::complex<double> wl(std::cos(a), std::sin(a));
    for (size_t i = 0; i < n; i += len) {
      std::complex<double> w(1, 0);
      for (size_t k = 0; k < len / 2; ++k) {
        const auto u = x[i + k], v = x[i + k + len / 2] * w;
        x[i + k] = u + v;
        x[i + k + len / 2] = u - v;
        w *= wl;
      }
    }
  }
}

double Bark(double hz) { return 13.0 * std::atan(0.00076 * hz) + 3.5 * std::atan(std::pow(hz / 7500.0, 2)); }

// Segment starts whose ref energy is within kSpeechRangeDb of the loudest.
std::vector<size_t> SpeechSegments(std::span<const float> ref, size_t n_usable, size_t len, size_t hop) {
  std::vector<std::pair<size_t, double>> seg;
  double max_e = 0;
  for (size_t s = 0; s + len <= n_usable; s += hop) {
    double e = 0;
    for (size_t i = s; i < s + len; ++i) e += static_cast<double>(ref[i]) * ref[i];
    seg.emplace_back(s, e);
    max_e = std::max(max_e, e);
  }
  std::vector<size_t> out;
  for (const auto& [s, e] : seg) {
    if (e > 0 && e >= max_e * std::pow(10.0, -kSpeechRangeDb / 10)) out.push_back(s);
  }
  return out;
}

size_t Usable(std::span<const float> ref, std::span<const float> out, int lag) {
  if (lag < 0 || out.size() <= static_cast<size_t>(lag)) return 0;
  return std::min(ref.size(), out.size() - static_cast<size_t>(lag));
}

}  // namespace

int BestLag(std::span<const float> ref, std::span<const float> out, int max_lag) {
  int best_lag = 0;
  double best = -1e300;
  for (int lag = 0; lag <= max_lag; ++lag) {
    const size_t n = Usable(ref, out, lag);
    double c = 0;
    for (size_t i = 0; i < n; ++i) c += static_cast<double>(ref[i]) * out[i + lag];
    if (c > best) best = c, best_lag = lag;
  }
  return best_lag;
}

double SegmentalSnrDb(std::span<const float> ref, std::span<const float> out, int lag) {
  const size_t len = 960;
  const size_t n = Usable(ref, out, lag);
  const auto segs = SpeechSegments(ref, n, len, len);
  if (segs.empty()) return 0;
  double sum = 0;
  for (size_t s : segs) {
    double e = 0, d = 0;
    for (size_t i = s; i < s + len; ++i) {
      e += static_cast<double>(ref[i]) * ref[i];
      const double diff = static_cast<double>(ref[i]) - out[i + static_cast<size_t>(lag)];
      d += diff * diff;
    }
    sum += std::clamp(10 * std::log10(e / std::max(d, 1e-20)), kMinDb, kMaxDb);
  }
  return sum / static_cast<double>(segs.size());
}

double FwSegSnrDb(std::span<const float> ref, std::span<const float> out, int lag, int sample_rate) {
  if (sample_rate < 8000) return 0;
  const size_t len = static_cast<size_t>(sample_rate) * 30 / 1000;
  const size_t hop = len / 4;
  size_t nfft = 1;
  while (nfft < len) nfft <<= 1;
  const size_t n = Usable(ref, out, lag);
  const auto segs = SpeechSegments(ref, n, len, hop);
  if (segs.empty()) return 0;
  // Band edges: 25 bands equally spaced in Bark between 50 Hz and 8 kHz (or Nyquist).
  constexpr int kBands = 25;
  const double hi_hz = std::min(8000.0, sample_rate / 2.0);
  const double b0 = Bark(50.0), b1 = Bark(hi_hz);
  std::vector<int> band_of_bin(nfft / 2 + 1, -1);
  for (size_t k = 0; k <= nfft / 2; ++k) {
    const double hz = static_cast<double>(k) * sample_rate / static_cast<double>(nfft);
    if (hz < 50.0 || hz >= hi_hz) continue;
    band_of_bin[k] = std::min(kBands - 1, static_cast<int>((Bark(hz) - b0) / (b1 - b0) * kBands));
  }
  std::vector<double> window(len);
  for (size_t i = 0; i < len; ++i) window[i] = 0.5 - 0.5 * std::cos(2 * std::numbers::pi * (i + 0.5) / len);
  std::vector<std::complex<double>> fx(nfft), fy(nfft);
  double total = 0;
  int frames = 0;
  for (size_t s : segs) {
    std::fill(fx.begin(), fx.end(), 0.0);
    std::fill(fy.begin(), fy.end(), 0.0);
    for (size_t i = 0; i < len; ++i) {
      fx[i] = ref[s + i] * window[i];
      fy[i] = out[s + i + static_cast<size_t>(lag)] * window[i];
    }
    Fft(fx);
    Fft(fy);
    std::vector<double> ex(kBands, 0.0), ey(kBands, 0.0);
    for (size_t k = 0; k <= nfft / 2; ++k) {
      if (band_of_bin[k] < 0) continue;
      ex[band_of_bin[k]] += std::norm(fx[k]);
      ey[band_of_bin[k]] += std::norm(fy[k]);
    }
    double sx = 0, sy = 0;
    for (int b = 0; b < kBands; ++b) sx += ex[b], sy += ey[b];
    if (sx <= 0) continue;
    double num = 0, den = 0;
    for (int b = 0; b < kBands; ++b) {
      const double x = std::sqrt(ex[b] / sx);
      const double y = sy > 0 ? std::sqrt(ey[b] / sy) : 0.0;
      const double snr = std::clamp(10 * std::log10(x * x / std::max((x - y) * (x - y), 1e-20)), kMinDb, kMaxDb);
      const double w = std::pow(x, 0.2);
      num += w * snr;
      den += w;
    }
    if (den > 0) {
      total += num / den;
      ++frames;
    }
  }
  return frames > 0 ? total / frames : 0;
}

}  // namespace holo::audio
