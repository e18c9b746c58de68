#include "audio/echo_canceller.h"

#include <speex/speex_echo.h>
#include <speex/speex_preprocess.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>
#include <unsupported/Eigen/FFT>

#include "webrtc/modules/audio_processing/include/audio_processing.h"

namespace holo::audio {
namespace {

constexpr int kDecimation = 4;          // 48 kHz → 12 kHz for the delay estimator
constexpr int kEstimateWindow = 16384;  // decimated samples (1.37 s)
constexpr int kEstimateEvery = 3000;    // decimated samples (0.25 s)
// twopath background step (normalised; stable below 2). Measured on the test
// room (docs/audio.md), near-end fwSNRseg under double talk 0.5 / 1.0 / 1.5:
// 23.6 / 24.4 / 24.5 dB; with −50 dBFS microphone noise 19.1 / 18.4 / 17.2 dB.
constexpr float kTwoPathStep = 1.0f;

int16_t ToS16(float v) { return static_cast<int16_t>(std::lround(std::clamp(v, -1.0f, 1.0f) * 32767.0f)); }

size_t NextPow2(size_t n) {
  size_t p = 1;
  while (p < n) p <<= 1;
  return p;
}

}  // namespace

const char* AecEngineName(AecEngine e) {
  switch (e) {
    case AecEngine::kTwoPath: return "twopath";
    case AecEngine::kSpeex: return "speex";
    case AecEngine::kWebRtc: return "webrtc";
  }
  return "?";
}

StatusOr<AecEngine> ParseAecEngine(const std::string& name) {
  if (name == "twopath") return AecEngine::kTwoPath;
  if (name == "speex") return AecEngine::kSpeex;
  if (name == "webrtc") return AecEngine::kWebRtc;
  return InvalidArgument("aec engine must be twopath, speex or webrtc, got '" + name + "'");
}

int EchoCancellerOptions::FilterMs() const {
  if (filter_ms > 0) return filter_ms;
  return engine == AecEngine::kTwoPath ? 140 : 80;
}

Status EchoCancellerOptions::Check() const {
  if (sample_rate != 48000) return InvalidArgument("echo canceller sample_rate must be 48000, got " + std::to_string(sample_rate));
  if (filter_ms != 0 && (filter_ms < 10 || filter_ms > 1000))
    return InvalidArgument("filter_ms must be 0 (engine default) or in 10..1000, got " + std::to_string(filter_ms));
  if (max_delay_ms < 10 || max_delay_ms > 1000)
    return InvalidArgument("max_delay_ms must be in 10..1000, got " + std::to_string(max_delay_ms));
  if (suppression < 0 || suppression > 2) return InvalidArgument("suppression must be 0, 1 or 2, got " + std::to_string(suppression));
  if (align_margin_ms < 0 || align_margin_ms > 100)
    return InvalidArgument("align_margin_ms must be in 0..100, got " + std::to_string(align_margin_ms));
  return OkStatus();
}

struct EchoCanceller::Engine {
  virtual ~Engine() = default;
  // `ref`: the aligned played block, interleaved stereo; `mic` → `out`, one 10 ms block.
  virtual void Process(const float* ref, const float* mic, float* out) = 0;
  // The reference now arrives `delta` samples later than before (> 0) or earlier.
  virtual void Realign(int /*delta*/) {}
};

namespace {

class SpeexEngine : public EchoCanceller::Engine {
 public:
  SpeexEngine(const EchoCancellerOptions& o, int block)
      : block_(block), aec_on_(o.echo_cancellation), mono_(o.mono_reference) {
    if (aec_on_) {
      echo_ = speex_echo_state_init_mc(block, o.FilterMs() * o.sample_rate / 1000, 1, mono_ ? 1 : 2);
      int rate = o.sample_rate;
      speex_echo_ctl(echo_, SPEEX_ECHO_SET_SAMPLING_RATE, &rate);
    }
    pre_ = speex_preprocess_state_init(block, o.sample_rate);
    int denoise = o.noise_suppression ? 1 : 0;
    speex_preprocess_ctl(pre_, SPEEX_PREPROCESS_SET_DENOISE, &denoise);
    int agc = 0;
    speex_preprocess_ctl(pre_, SPEEX_PREPROCESS_SET_AGC, &agc);
    if (aec_on_) {
      speex_preprocess_ctl(pre_, SPEEX_PREPROCESS_SET_ECHO_STATE, echo_);
      int sup = -20 - 10 * o.suppression, active = sup / 2;
      speex_preprocess_ctl(pre_, SPEEX_PREPROCESS_SET_ECHO_SUPPRESS, &sup);
      speex_preprocess_ctl(pre_, SPEEX_PREPROCESS_SET_ECHO_SUPPRESS_ACTIVE, &active);
    }
    mic_.resize(block);
    ref_.resize(2 * block);
    out_.resize(block);
  }
  ~SpeexEngine() override {
    if (echo_) speex_echo_state_destroy(echo_);
    if (pre_) speex_preprocess_state_destroy(pre_);
  }
  bool ok() const { return pre_ != nullptr && (!aec_on_ || echo_ != nullptr); }
  void Process(const float* ref, const float* mic, float* out) override {
    for (int i = 0; i < block_; ++i) mic_[i] = ToS16(mic[i]);
    if (aec_on_) {
      if (mono_) {
        for (int i = 0; i < block_; ++i) ref_[i] = ToS16(0.5f * (ref[2 * i] + ref[2 * i + 1]));
      } else {
        for (int i = 0; i < 2 * block_; ++i) ref_[i] = ToS16(ref[i]);
      }
      speex_echo_cancellation(echo_, mic_.data(), ref_.data(), out_.data());
    } else {
      out_ = mic_;
    }
    speex_preprocess_run(pre_, out_.data());
    for (int i = 0; i < block_; ++i) out[i] = static_cast<float>(out_[i]) / 32768.0f;
  }

 private:
  int block_;
  bool aec_on_, mono_;
  SpeexEchoState* echo_ = nullptr;
  SpeexPreprocessState* pre_ = nullptr;
  std::vector<int16_t> mic_, ref_, out_;
};

// Partitioned-block frequency-domain adaptive filter ("multi-delay filter"):
// blocks of L samples (10 ms), FFTs of 2L, P partitions of L per reference
// channel (P·L ≥ the filter length), the update normalised per frequency bin
// by the smoothed reference power of all channels and gradient-constrained
// (overlap-save), so it is the exact block-LMS of a P·L-tap filter per channel.
//
// Two copies of the filter ("two-path"): the background adapts on every block
// in which something was played, at a normalised step (kTwoPathStep, shared
// between partitions in proportion to their weight, smaller in bins already
// down to the noise floor); the foreground makes the output and never adapts
// by itself. The background is copied into the foreground only when its
// error has been clearly lower (< 0.7×, smoothed over two blocks) for two
// blocks in a row and lower than the microphone itself. While the near end
// talks the background's error holds the near-end speech, the background
// drifts, its error rises above the foreground's and nothing is copied: the
// output filter keeps the echo path it learnt in single talk. That is the
// double-talk protection, with no level threshold to tune (a Geigel detector
// needs the echo path's loss; a coherence detector needs its own smoothing).
// Measured: the echo residual under double talk stays at 28 dB, 0.4 dB
// fwSNRseg from no echo (docs/audio.md).
class TwoPathFilter {
 public:
  TwoPathFilter(int block, int partitions, int channels, float step)
      : L_(block), N_(2 * block), K_(block + 1), P_(partitions), C_(channels), step_(step) {
    fft_.SetFlag(Eigen::FFT<float>::HalfSpectrum);
    const size_t bins = static_cast<size_t>(K_) * P_ * C_;
    x_spec_.assign(bins, {0, 0});
    w_back_.assign(bins, {0, 0});
    w_fore_.assign(bins, {0, 0});
    x_prev_.assign(static_cast<size_t>(C_ * L_), 0.0f);
    power_.assign(static_cast<size_t>(K_), 0.0f);
    err_power_.assign(static_cast<size_t>(K_), 0.0f);
    err_floor_.assign(static_cast<size_t>(K_), 0.0f);
    share_.assign(static_cast<size_t>(P_) * C_, 1.0f);
    time_.assign(static_cast<size_t>(N_), 0.0f);
    spec_.assign(static_cast<size_t>(K_), {0, 0});
    err_spec_.assign(static_cast<size_t>(K_), {0, 0});
    y_back_.assign(static_cast<size_t>(L_), 0.0f);
    y_fore_.assign(static_cast<size_t>(L_), 0.0f);
  }

  // `ref`: L frames of C interleaved channels; `mic` → `out` (foreground error), L samples.
  void Process(const float* ref, const float* mic, float* out) {
    // Newest partition first: shift the reference spectra by one block.
    for (int c = 0; c < C_; ++c) {
      std::complex<float>* xs = Spectra(x_spec_, c, 0);
      std::move_backward(xs, xs + static_cast<size_t>(K_) * (P_ - 1), xs + static_cast<size_t>(K_) * P_);
      float* prev = x_prev_.data() + static_cast<size_t>(c) * L_;
      for (int i = 0; i < L_; ++i) {
        time_[static_cast<size_t>(i)] = prev[i];
        prev[i] = time_[static_cast<size_t>(L_ + i)] = ref[static_cast<size_t>(C_ * i + c)];
      }
      fft_.fwd(xs, time_.data(), N_);
    }
    for (int k = 0; k < K_; ++k) {
      float s = 0;
      for (int c = 0; c < C_; ++c) s += std::norm(Spectra(x_spec_, c, 0)[k]);
      power_[static_cast<size_t>(k)] = blocks_ == 0 ? s : 0.9f * power_[static_cast<size_t>(k)] + 0.1f * s;
    }
    ++blocks_;
    Filter(w_back_, y_back_.data());
    Filter(w_fore_, y_fore_.data());
    double e_back = 0, e_fore = 0, e_mic = 0;
    for (int i = 0; i < L_; ++i) {
      const float eb = mic[i] - y_back_[static_cast<size_t>(i)], ef = mic[i] - y_fore_[static_cast<size_t>(i)];
      time_[static_cast<size_t>(i)] = 0.0f;
      time_[static_cast<size_t>(L_ + i)] = eb;
      out[i] = ef;
      e_back += static_cast<double>(eb) * eb;
      e_fore += static_cast<double>(ef) * ef;
      e_mic += static_cast<double>(mic[i]) * mic[i];
    }
    if (hold_ > 0) {  // the reference history straddles a re-alignment: learn nothing from it
      --hold_;
      return;
    }
    // Nothing played (below −70 dBFS): nothing to learn, and a normalised
    // step on a near-silent reference would only chase the near end.
    double ref_energy = 0;
    for (int i = 0; i < C_ * L_; ++i) ref_energy += static_cast<double>(ref[i]) * ref[i];
    if (ref_energy > 1e-7 * C_ * L_) Adapt();
    smooth_back_ = 0.5 * smooth_back_ + 0.5 * e_back;
    smooth_fore_ = 0.5 * smooth_fore_ + 0.5 * e_fore;
    smooth_mic_ = 0.5 * smooth_mic_ + 0.5 * e_mic;
    if (smooth_back_ < 0.7 * smooth_fore_ && smooth_back_ < smooth_mic_) {
      if (++better_ >= 2) {
        w_fore_ = w_back_;
        better_ = 0;
      }
    } else {
      better_ = 0;
    }
    // The echo path changed (the foreground adds echo): take whatever the background has.
    if (smooth_fore_ > 2.0 * smooth_mic_ && smooth_back_ < smooth_fore_) w_fore_ = w_back_;
  }

  // The reference stream moved `delta` samples later: an echo tap at lag n
  // is now at n − delta. Both filters keep what they learnt, shifted; the
  // blocks whose history straddles the move do not adapt.
  void Realign(int delta) {
    for (auto* w : {&w_back_, &w_fore_}) {
      for (int c = 0; c < C_; ++c) {
        std::vector<float> taps(static_cast<size_t>(P_) * L_);
        for (int p = 0; p < P_; ++p) {
          fft_.inv(time_.data(), Spectra(*w, c, p), N_);
          std::copy(time_.begin(), time_.begin() + L_, taps.begin() + static_cast<std::ptrdiff_t>(p) * L_);
        }
        for (int p = 0; p < P_; ++p) {
          std::fill(time_.begin(), time_.end(), 0.0f);
          for (int i = 0; i < L_; ++i) {
            const int64_t from = static_cast<int64_t>(p) * L_ + i + delta;
            if (from >= 0 && from < static_cast<int64_t>(taps.size()))
              time_[static_cast<size_t>(i)] = taps[static_cast<size_t>(from)];
          }
          fft_.fwd(Spectra(*w, c, p), time_.data(), N_);
        }
      }
    }
    hold_ = P_;
    better_ = 0;
  }

 private:
  std::complex<float>* Spectra(std::vector<std::complex<float>>& v, int channel, int partition) {
    return v.data() + (static_cast<size_t>(channel) * P_ + static_cast<size_t>(partition)) * K_;
  }
  // y = the last L samples of IFFT(Σ W·X) (overlap-save).
  void Filter(std::vector<std::complex<float>>& w, float* y) {
    std::fill(spec_.begin(), spec_.end(), std::complex<float>(0, 0));
    for (int j = 0; j < C_ * P_; ++j) {
      const std::complex<float>* wj = w.data() + static_cast<size_t>(j) * K_;
      const std::complex<float>* xj = x_spec_.data() + static_cast<size_t>(j) * K_;
      for (int k = 0; k < K_; ++k) spec_[static_cast<size_t>(k)] += wj[k] * xj[k];
    }
    fft_.inv(time_.data(), spec_.data(), N_);
    std::copy(time_.begin() + L_, time_.end(), y);
  }
  // Background update from its error (in time_[L..2L), zeros before).
  void Adapt() {
    fft_.fwd(err_spec_.data(), time_.data(), N_);
    float mean = 0;
    for (float v : power_) mean += v;
    mean /= static_cast<float>(K_);
    const float reg = 1e-2f * mean + 1e-9f;  // bins the far end hardly excites do not blow up
    // Where the background's error is down to the microphone's noise floor
    // there is no echo left to learn from, only noise to follow: the step
    // shrinks there (1 − 3·floor/error). The floor per bin is the smoothed
    // error power's minimum, allowed to rise 0.2 % per block (0.9 dB/s).
    // Measured with −50 dBFS microphone noise: single-talk ERLE 20.8 → 25.0 dB;
    // unchanged at −80 dBFS (docs/audio.md).
    for (int k = 0; k < K_; ++k) {
      const size_t b = static_cast<size_t>(k);
      const float pe = std::norm(err_spec_[b]);
      err_power_[b] = blocks_ <= 1 ? pe : 0.7f * err_power_[b] + 0.3f * pe;
      err_floor_[b] = blocks_ <= 1 ? err_power_[b] : std::min(err_power_[b], err_floor_[b] * 1.002f);
      const float keep = std::max(0.0f, 1.0f - 3.0f * err_floor_[b] / (err_power_[b] + 1e-20f));
      err_spec_[b] *= keep * step_ / (static_cast<float>(P_) * power_[b] + reg);
    }
    // Proportionate step (IPNLMS, α = 0, per partition): half of the step is
    // shared evenly, half in proportion to each partition's coefficient norm,
    // so the direct sound and early reflections converge faster than the
    // near-empty late partitions. Measured (docs/audio.md): 140 ms, test room,
    // single-talk ERLE 36.2 → 43.4 dB, fwSNRseg double talk 24.5 → 24.7 dB;
    // 250 ms in a RT60 0.5 s room 25.4 → 28.8 dB.
    const int J = C_ * P_;
    double total = 0;
    for (int j = 0; j < J; ++j) {
      double e = 0;
      const std::complex<float>* wj = w_back_.data() + static_cast<size_t>(j) * K_;
      for (int k = 0; k < K_; ++k) e += std::norm(wj[k]);
      share_[static_cast<size_t>(j)] = static_cast<float>(std::sqrt(e));
      total += std::sqrt(e);
    }
    for (int j = 0; j < J; ++j)
      share_[static_cast<size_t>(j)] =
          0.5f + 0.5f * static_cast<float>(J * share_[static_cast<size_t>(j)] / (total + 1e-12));
    for (int j = 0; j < J; ++j) {
      std::complex<float>* wj = w_back_.data() + static_cast<size_t>(j) * K_;
      const std::complex<float>* xj = x_spec_.data() + static_cast<size_t>(j) * K_;
      const float g = share_[static_cast<size_t>(j)];
      for (int k = 0; k < K_; ++k)
        spec_[static_cast<size_t>(k)] = g * std::conj(xj[k]) * err_spec_[static_cast<size_t>(k)];
      // Gradient constraint: keep the first L taps of the correlation only.
      fft_.inv(time_.data(), spec_.data(), N_);
      std::fill(time_.begin() + L_, time_.end(), 0.0f);
      fft_.fwd(spec_.data(), time_.data(), N_);
      for (int k = 0; k < K_; ++k) wj[k] += spec_[static_cast<size_t>(k)];
    }
  }

  int L_, N_, K_, P_, C_;
  float step_;
  Eigen::FFT<float> fft_;
  std::vector<std::complex<float>> x_spec_, w_back_, w_fore_, spec_, err_spec_;
  std::vector<float> x_prev_, power_, time_, y_back_, y_fore_;
  std::vector<float> err_power_, err_floor_;  // background error power per bin, smoothed; its floor
  std::vector<float> share_;                   // step share per partition (proportionate)
  int64_t blocks_ = 0;
  int hold_ = 0;
  double smooth_back_ = 0, smooth_fore_ = 0, smooth_mic_ = 0;
  int better_ = 0;
};

// The two-path filter for the echo, then speexdsp's preprocessor for noise
// only (its residual echo suppression needs speexdsp's own echo state, and
// measured it costs the near end more than it removes: docs/audio.md).
class TwoPathEngine : public EchoCanceller::Engine {
 public:
  TwoPathEngine(const EchoCancellerOptions& o, int block)
      : block_(block), aec_on_(o.echo_cancellation), ns_on_(o.noise_suppression), mono_(o.mono_reference) {
    if (aec_on_) {
      const int partitions = (o.FilterMs() * o.sample_rate / 1000 + block - 1) / block;
      filter_ = std::make_unique<TwoPathFilter>(block, partitions, mono_ ? 1 : 2, kTwoPathStep);
    }
    if (ns_on_) {
      pre_ = speex_preprocess_state_init(block, o.sample_rate);
      if (pre_) {
        int on = 1, off = 0;
        speex_preprocess_ctl(pre_, SPEEX_PREPROCESS_SET_DENOISE, &on);
        speex_preprocess_ctl(pre_, SPEEX_PREPROCESS_SET_AGC, &off);
      }
    }
    ref_.resize(2 * static_cast<size_t>(block));
    err_.resize(static_cast<size_t>(block));
    pcm_.resize(static_cast<size_t>(block));
  }
  ~TwoPathEngine() override {
    if (pre_) speex_preprocess_state_destroy(pre_);
  }
  void Realign(int delta) override {
    if (filter_) filter_->Realign(delta);
  }
  bool ok() const { return !ns_on_ || pre_ != nullptr; }
  void Process(const float* ref, const float* mic, float* out) override {
    const float* cleaned = mic;
    if (aec_on_) {
      if (mono_) {
        for (int i = 0; i < block_; ++i) ref_[static_cast<size_t>(i)] = 0.5f * (ref[2 * i] + ref[2 * i + 1]);
        filter_->Process(ref_.data(), mic, err_.data());
      } else {
        filter_->Process(ref, mic, err_.data());
      }
      cleaned = err_.data();
    }
    if (!ns_on_) {
      std::copy(cleaned, cleaned + block_, out);
      return;
    }
    for (int i = 0; i < block_; ++i) pcm_[static_cast<size_t>(i)] = ToS16(cleaned[i]);
    speex_preprocess_run(pre_, pcm_.data());
    for (int i = 0; i < block_; ++i) out[i] = static_cast<float>(pcm_[static_cast<size_t>(i)]) / 32768.0f;
  }

 private:
  int block_;
  bool aec_on_, ns_on_, mono_;
  std::unique_ptr<TwoPathFilter> filter_;
  SpeexPreprocessState* pre_ = nullptr;
  std::vector<float> ref_, err_;
  std::vector<int16_t> pcm_;
};

class WebRtcEngine : public EchoCanceller::Engine {
 public:
  WebRtcEngine(const EchoCancellerOptions& o, int block)
      : block_(block),
        rate_(o.sample_rate),
        delay_ms_(o.align_margin_ms),
        aec_on_(o.echo_cancellation),
        mono_(o.mono_reference) {
    webrtc::Config config;
    // Longer filter and conservative far-end read pointer: rooms ring for 100+ ms.
    config.Set<webrtc::ExtendedFilter>(new webrtc::ExtendedFilter(true));
    apm_.reset(webrtc::AudioProcessing::Create(config));
    if (!apm_) return;
    apm_->high_pass_filter()->Enable(true);
    apm_->echo_cancellation()->Enable(o.echo_cancellation);
    apm_->echo_cancellation()->set_suppression_level(
        static_cast<webrtc::EchoCancellation::SuppressionLevel>(o.suppression));
    apm_->noise_suppression()->set_level(webrtc::NoiseSuppression::kModerate);
    apm_->noise_suppression()->Enable(o.noise_suppression);
    left_.resize(block);
    right_.resize(block);
  }
  bool ok() const { return apm_ != nullptr; }
  void Process(const float* ref, const float* mic, float* out) override {
    const webrtc::StreamConfig stereo(rate_, 2), mono(rate_, 1);
    if (aec_on_) {
      for (int i = 0; i < block_; ++i) {
        if (mono_) {
          left_[i] = 0.5f * (ref[2 * i] + ref[2 * i + 1]);
        } else {
          left_[i] = ref[2 * i];
          right_[i] = ref[2 * i + 1];
        }
      }
      const float* rsrc[2] = {left_.data(), right_.data()};
      float* rdst[2] = {left_.data(), right_.data()};
      apm_->ProcessReverseStream(rsrc, mono_ ? mono : stereo, mono_ ? mono : stereo, rdst);
      // The reference is already aligned: what remains is the causality margin.
      apm_->set_stream_delay_ms(delay_ms_);
    }
    std::copy(mic, mic + block_, out);
    const float* src[1] = {out};
    float* dst[1] = {out};
    apm_->ProcessStream(src, mono, mono, dst);
  }

 private:
  int block_, rate_, delay_ms_;
  bool aec_on_, mono_;
  std::unique_ptr<webrtc::AudioProcessing> apm_;
  std::vector<float> left_, right_;
};

}  // namespace

EchoCanceller::EchoCanceller(const EchoCancellerOptions& o) : options_(o), block_(o.sample_rate / 100) {}
EchoCanceller::~EchoCanceller() = default;

StatusOr<std::unique_ptr<EchoCanceller>> EchoCanceller::Create(const EchoCancellerOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<EchoCanceller> ec(new EchoCanceller(options));
  if (options.engine == AecEngine::kTwoPath) {
    auto e = std::make_unique<TwoPathEngine>(options, ec->block_);
    if (!e->ok()) return Internal("speexdsp: could not create the noise suppressor");
    ec->engine_ = std::move(e);
  } else if (options.engine == AecEngine::kSpeex) {
    auto e = std::make_unique<SpeexEngine>(options, ec->block_);
    if (!e->ok()) return Internal("speexdsp: could not create the echo canceller / preprocessor");
    ec->engine_ = std::move(e);
  } else {
    auto e = std::make_unique<WebRtcEngine>(options, ec->block_);
    if (!e->ok()) return Internal("webrtc audio processing: AudioProcessing::Create failed");
    ec->engine_ = std::move(e);
  }
  return ec;
}

void EchoCanceller::PushPlayed(std::span<const float> stereo) {
  const size_t frames = stereo.size() / 2;
  played_.insert(played_.end(), stereo.begin(), stereo.begin() + static_cast<std::ptrdiff_t>(2 * frames));
  played_count_ += static_cast<int64_t>(frames);
  // Keep the longest delay plus a second of history.
  const int64_t keep = static_cast<int64_t>(options_.max_delay_ms + 1000) * options_.sample_rate / 1000;
  while (played_count_ - played_base_ > keep) {
    played_.pop_front();
    played_.pop_front();
    ++played_base_;
  }
  if (!options_.echo_cancellation) return;
  for (size_t i = 0; i < frames; ++i) {
    far_acc_.push_back(0.5f * (stereo[2 * i] + stereo[2 * i + 1]));
    if (far_acc_.size() == kDecimation) {
      float s = 0;
      for (float v : far_acc_) s += v;
      far_dec_.push_back(s / kDecimation);
      ++far_dec_count_;
      far_acc_.clear();
    }
  }
  // Playout runs ahead of capture by up to a block or two: keep some spare.
  const size_t far_keep = kEstimateWindow + static_cast<size_t>(options_.max_delay_ms) * 12 + 4 * 12000 / 10;
  while (far_dec_.size() > far_keep) far_dec_.pop_front();
}

std::vector<float> EchoCanceller::ProcessCapture(std::span<const float> mic) {
  mic_pending_.insert(mic_pending_.end(), mic.begin(), mic.end());
  size_t done = 0;
  std::vector<float> out_block(static_cast<size_t>(block_));
  while (mic_pending_.size() - done >= static_cast<size_t>(block_)) {
    ProcessBlock(mic_pending_.data() + done, out_block.data());
    out_ready_.insert(out_ready_.end(), out_block.begin(), out_block.end());
    done += static_cast<size_t>(block_);
  }
  mic_pending_.erase(mic_pending_.begin(), mic_pending_.begin() + static_cast<std::ptrdiff_t>(done));
  // Hand back as many samples as came in, oldest first. When the caller's
  // sizes are not whole 10 ms blocks the stream starts with up to one block of
  // zeros (a constant delay from then on).
  std::vector<float> out(mic.size(), 0.0f);
  const size_t n = std::min(out_ready_.size(), mic.size());
  std::copy(out_ready_.begin(), out_ready_.begin() + static_cast<std::ptrdiff_t>(n),
            out.end() - static_cast<std::ptrdiff_t>(n));
  out_ready_.erase(out_ready_.begin(), out_ready_.begin() + static_cast<std::ptrdiff_t>(n));
  return out;
}

void EchoCanceller::ProcessBlock(const float* mic, float* out) {
  if (options_.echo_cancellation) {
    for (int i = 0; i < block_; ++i) {
      mic_acc_.push_back(mic[i]);
      if (mic_acc_.size() == kDecimation) {
        float s = 0;
        for (float v : mic_acc_) s += v;
        mic_dec_.push_back(s / kDecimation);
        ++mic_dec_count_;
        mic_acc_.clear();
        ++since_estimate_;
      }
    }
    while (mic_dec_.size() > kEstimateWindow) mic_dec_.pop_front();
    if (since_estimate_ >= kEstimateEvery && mic_dec_.size() == kEstimateWindow) {
      since_estimate_ = 0;
      EstimateDelay();
    }
  }
  // The reference block for these mic samples: played `applied_delay_` samples earlier.
  std::vector<float> ref(2 * static_cast<size_t>(block_), 0.0f);
  const int64_t start = mic_count_ - applied_delay_;
  for (int i = 0; i < block_; ++i) {
    const int64_t k = start + i;
    if (k < played_base_ || k >= played_count_) continue;
    const size_t at = static_cast<size_t>(2 * (k - played_base_));
    ref[2 * static_cast<size_t>(i)] = played_[at];
    ref[2 * static_cast<size_t>(i) + 1] = played_[at + 1];
  }
  engine_->Process(ref.data(), mic, out);
  mic_count_ += block_;
}

void EchoCanceller::EstimateDelay() {
  const size_t max_lag = static_cast<size_t>(options_.max_delay_ms) * 12;
  // The far segment ends at the same time as the mic segment (playout may have
  // run ahead: those samples are not used); it reaches max_lag further back.
  const int64_t far_first = far_dec_count_ - static_cast<int64_t>(far_dec_.size());
  const int64_t seg_start = mic_dec_count_ - static_cast<int64_t>(kEstimateWindow + max_lag);
  if (seg_start < far_first || mic_dec_count_ > far_dec_count_) return;
  double far_e = 0, mic_e = 0;
  for (float v : mic_dec_) mic_e += static_cast<double>(v) * v;
  const size_t f0 = static_cast<size_t>(seg_start - far_first);
  for (size_t i = f0; i < f0 + kEstimateWindow + max_lag; ++i) far_e += static_cast<double>(far_dec_[i]) * far_dec_[i];
  if (far_e / static_cast<double>(kEstimateWindow + max_lag) < 1e-7 || mic_e / kEstimateWindow < 1e-9) return;
  const size_t n = NextPow2(2 * kEstimateWindow + max_lag);
  std::vector<float> m(n, 0.0f), f(n, 0.0f);
  for (size_t i = 0; i < kEstimateWindow; ++i) m[i] = mic_dec_[i];
  for (size_t i = 0; i < kEstimateWindow + max_lag; ++i) f[i] = far_dec_[f0 + i];
  Eigen::FFT<float> fft;
  std::vector<std::complex<float>> M, F;
  fft.fwd(M, m);
  fft.fwd(F, f);
  for (size_t i = 0; i < M.size(); ++i) {
    const std::complex<float> c = std::conj(M[i]) * F[i];
    const float a = std::abs(c);
    M[i] = a > 1e-20f ? c / a : std::complex<float>(0, 0);  // PHAT weighting
  }
  std::vector<float> corr;
  fft.inv(corr, M);
  // corr[j] = Σ m[t] f[t + j]; f[t + j] is the far end (max_lag − j) decimated samples before m[t].
  size_t best = 0;
  double best_v = -1, sum_sq = 0;
  for (size_t j = 0; j <= max_lag; ++j) {
    sum_sq += static_cast<double>(corr[j]) * corr[j];
    if (corr[j] > best_v) {
      best_v = corr[j];
      best = j;
    }
  }
  const double rms = std::sqrt(sum_sq / static_cast<double>(max_lag + 1));
  if (rms <= 0 || best_v / rms < 8.0) return;  // no clear peak: keep what we have
  // Strong reflections make peaks of their own at longer lags: the delay is
  // the shortest lag (largest j) with a peak of at least half the largest.
  for (size_t j = max_lag; j > best; --j) {
    if (corr[j] >= 0.5 * best_v && corr[j] >= corr[j - 1] && (j == max_lag || corr[j] >= corr[j + 1])) {
      best = j;
      break;
    }
  }
  const double lag = static_cast<double>(max_lag - best) * kDecimation;  // samples at 48 kHz
  const bool agrees = last_estimate_ >= 0 && std::abs(lag - last_estimate_) <= 2 * kDecimation;
  last_estimate_ = lag;
  if (!agrees) return;
  confident_delay_ms_ = lag * 1000.0 / options_.sample_rate;
  const int margin = options_.align_margin_ms * options_.sample_rate / 1000;
  const int wanted = std::max(0, static_cast<int>(lag) - margin);
  // Moving the reference makes the filter re-adapt: only for a real change (> 1 ms).
  if (std::abs(wanted - applied_delay_) > options_.sample_rate / 1000) {
    engine_->Realign(wanted - applied_delay_);
    applied_delay_ = wanted;
    ++updates_;
  }
}

double EchoCanceller::estimated_delay_ms() const { return confident_delay_ms_; }
int EchoCanceller::delay_updates() const { return updates_; }

EchoPath MakeEchoPath(const EchoPathOptions& o) {
  const int rate = 48000;
  const size_t d = static_cast<size_t>(o.delay_ms * rate / 1000.0);
  const size_t len = d + static_cast<size_t>(o.ir_ms * rate / 1000.0);
  EchoPath p;
  p.ir_left.assign(len, 0.0f);
  p.ir_right.assign(len, 0.0f);
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int ch = 0; ch < 2; ++ch) {
    auto& ir = ch == 0 ? p.ir_left : p.ir_right;
    // The right speaker is a little further from the microphone.
    const size_t direct = d + (ch == 0 ? 0 : static_cast<size_t>(0.0006 * rate));
    ir[direct] = ch == 0 ? 1.0f : 0.8f;
    for (int r = 0; r < 6; ++r) {  // early reflections 2..20 ms after the direct sound
      const size_t at = direct + static_cast<size_t>((0.002 + 0.018 * u(rng)) * rate);
      if (at < len) ir[at] += (u(rng) < 0.5f ? -1.0f : 1.0f) * (0.2f + 0.3f * u(rng));
    }
    const double decay = 6.907755 / (o.rt60_s * rate);  // ln(1000): −60 dB after rt60
    float lp = 0;
    for (size_t i = direct + static_cast<size_t>(0.005 * rate); i < len; ++i) {
      lp = 0.6f * lp + 0.4f * g(rng);  // walls absorb highs: a gentle low-pass on the tail
      ir[i] += 0.08f * lp * static_cast<float>(std::exp(-decay * static_cast<double>(i - direct)));
    }
    for (float& v : ir) v *= static_cast<float>(o.gain);
  }
  return p;
}

std::vector<float> ApplyEchoPath(const EchoPath& path, std::span<const float> played) {
  const size_t frames = played.size() / 2;
  const size_t ir = std::max(path.ir_left.size(), path.ir_right.size());
  const size_t n = NextPow2(frames + ir);
  Eigen::FFT<float> fft;
  std::vector<std::complex<float>> acc(n, {0, 0});
  for (int ch = 0; ch < 2; ++ch) {
    std::vector<float> x(n, 0.0f), h(n, 0.0f);
    for (size_t i = 0; i < frames; ++i) x[i] = played[2 * i + static_cast<size_t>(ch)];
    const auto& src = ch == 0 ? path.ir_left : path.ir_right;
    std::copy(src.begin(), src.end(), h.begin());
    std::vector<std::complex<float>> X, H;
    fft.fwd(X, x);
    fft.fwd(H, h);
    for (size_t i = 0; i < n; ++i) acc[i] += X[i] * H[i];
  }
  std::vector<float> y;
  fft.inv(y, acc);
  y.resize(frames);
  return y;
}

double ErleDb(std::span<const float> echo, std::span<const float> out, std::span<const float> near, size_t begin,
              size_t end, int near_lag) {
  end = std::min({end, echo.size(), out.size()});
  double e = 0, r = 0;
  for (size_t i = begin; i < end; ++i) {
    const int64_t k = static_cast<int64_t>(i) - near_lag;
    const float nv = near.empty() || k < 0 || k >= static_cast<int64_t>(near.size()) ? 0.0f : near[static_cast<size_t>(k)];
    const double res = out[i] - nv;
    e += static_cast<double>(echo[i]) * echo[i];
    r += res * res;
  }
  return 10.0 * std::log10((e + 1e-20) / (r + 1e-20));
}

namespace {

double SnrDb(std::span<const float> clean, std::span<const float> x, size_t skip) {
  const size_t f = 960;
  const size_t n = std::min(clean.size(), x.size());
  std::vector<double> ce, xe;
  for (size_t i = skip; i + f <= n; i += f) {
    double c = 0, e = 0;
    for (size_t k = i; k < i + f; ++k) {
      c += static_cast<double>(clean[k]) * clean[k];
      e += static_cast<double>(x[k]) * x[k];
    }
    ce.push_back(c);
    xe.push_back(e);
  }
  const double peak = ce.empty() ? 0 : *std::max_element(ce.begin(), ce.end());
  double sp = 0, pa = 0;
  int ns = 0, np = 0;
  for (size_t i = 0; i < ce.size(); ++i) {
    if (ce[i] >= peak * 1e-3) {
      sp += xe[i];
      ++ns;
    } else if (ce[i] <= peak * 1e-5) {
      pa += xe[i];
      ++np;
    }
  }
  if (ns == 0 || np == 0) return 0;
  sp /= ns;
  pa /= np;
  return 10.0 * std::log10(std::max(sp - pa, 1e-20) / std::max(pa, 1e-20));
}

}  // namespace

double NoiseSuppressionGainDb(std::span<const float> clean, std::span<const float> noisy,
                              std::span<const float> processed, size_t skip) {
  return SnrDb(clean, processed, skip) - SnrDb(clean, noisy, skip);
}

}  // namespace holo::audio
