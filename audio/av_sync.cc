#include "audio/av_sync.h"

#include <algorithm>
#include <deque>
#include <cmath>
#include <string>

#include "common/quantile.h"

namespace holo::audio {
namespace {

// Sample vectors for the run's statistics keep at most this many values
// (9 hours of pictures at 30 fps).
constexpr size_t kMaxSamples = 1000000;

void Keep(std::vector<float>* v, double x) {
  if (v->size() < kMaxSamples) v->push_back(static_cast<float>(x));
}

// The delays (ms) of a window of (time, delay) samples, sorted.
std::vector<double> SortedDelays(const std::deque<std::pair<int64_t, double>>& window) {
  std::vector<double> d;
  d.reserve(window.size());
  for (const auto& [t, ms] : window) d.push_back(ms);
  std::sort(d.begin(), d.end());
  return d;
}

// Quantile q of sorted, non-empty delays, rounded up: as late as that share
// of them at least.
double UpperQuantile(const std::vector<double>& sorted, double q) {
  const auto k = static_cast<size_t>(std::ceil(q * static_cast<double>(sorted.size() - 1)));
  return sorted[std::min(sorted.size() - 1, k)];
}

}  // namespace

Status AvSyncOptions::Check() const {
  if (!(max_voice_delay_ms >= 0 && max_voice_delay_ms <= 10000))
    return InvalidArgument("max_voice_delay_ms must be in 0..10000, got " + std::to_string(max_voice_delay_ms));
  if (!(max_picture_delay_ms >= 0 && max_picture_delay_ms <= 10000))
    return InvalidArgument("max_picture_delay_ms must be in 0..10000, got " + std::to_string(max_picture_delay_ms));
  if (!(window_s > 0 && window_s <= 60)) return InvalidArgument("window_s must be in (0, 60], got " + std::to_string(window_s));
  if (!(picture_quantile >= 0.5 && picture_quantile <= 1.0))
    return InvalidArgument("picture_quantile must be in [0.5, 1], got " + std::to_string(picture_quantile));
  if (!(deadband_ms >= 0)) return InvalidArgument("deadband_ms must be >= 0");
  if (!(update_interval_ms >= 0)) return InvalidArgument("update_interval_ms must be >= 0");
  if (!(early_limit_ms > 0 && late_limit_ms > 0)) return InvalidArgument("early_limit_ms and late_limit_ms must be > 0");
  if (!(voice_timeout_ms > 0)) return InvalidArgument("voice_timeout_ms must be > 0");
  return OkStatus();
}

AvSync::AvSync(AvSyncOptions options) : options_(options) {}

double AvSync::VoiceMaxLocked(double Voice::*delay, int64_t now_us) const {
  double largest = -1.0;
  const auto timeout_us = static_cast<int64_t>(options_.voice_timeout_ms * 1000.0);
  for (const auto& [id, v] : voices_)
    if (v.last_playout_us >= now_us - timeout_us) largest = std::max(largest, v.*delay);
  return largest;
}

int64_t AvSync::PictureReady(int64_t capture_us, int64_t ready_us) {
  std::lock_guard<std::mutex> l(mu_);
  int64_t show = ready_us;
  const double render_ms = Quantile(std::vector<double>(render_ms_.begin(), render_ms_.end()), 0.5);
  last_picture_us_ = std::max(last_picture_us_, ready_us);
  if (options_.hold_pictures || options_.pace_pictures)
    natural_delays_.emplace_back(ready_us, static_cast<double>(ready_us - capture_us) / 1000.0 + render_ms);
  if (options_.hold_pictures) UpdateVoiceTargetLocked(ready_us);
  // Held until the voice of the same instant plays: its actual delay (sync
  // included) with a picture jitter buffer, else only its own delay.
  const double voice =
      !options_.enabled ? -1.0
                        : VoiceMaxLocked(options_.hold_pictures ? &Voice::delay_ms : &Voice::natural_ms, ready_us);
  // Without a voice, paced pictures keep the delay most of them have (their
  // natural delays' quantile over the window).
  const double target = voice >= 0 ? voice : (options_.pace_pictures ? PaceDelayLocked(ready_us) : -1.0);
  if (target >= 0) {
    // Rendering takes time: start it so that the picture is visible when
    // its voice plays.
    const auto want = capture_us + static_cast<int64_t>(std::llround((target - render_ms) * 1000.0));
    if (want > ready_us) {
      const auto limit = ready_us + static_cast<int64_t>(std::llround(options_.max_picture_delay_ms * 1000.0));
      if (want > limit) ++n_.pictures_hold_capped;
      show = std::min(want, limit);
    }
  }
  holds_[capture_us] = static_cast<double>(show - ready_us) / 1000.0;
  // Pictures never displayed (dropped for a newer one) leave their entry: keep 10 s.
  while (!holds_.empty() && holds_.begin()->first < capture_us - 10000000) holds_.erase(holds_.begin());
  return show;
}

double AvSync::PaceDelayLocked(int64_t now_us) {
  TrimWindowsLocked(now_us);
  if (natural_delays_.empty()) return -1.0;
  return UpperQuantile(SortedDelays(natural_delays_), options_.picture_quantile);
}

void AvSync::TrimWindowsLocked(int64_t now_us) {
  const auto window_us = static_cast<int64_t>(options_.window_s * 1e6);
  while (!picture_delays_.empty() && picture_delays_.front().first < now_us - window_us) picture_delays_.pop_front();
  while (!natural_delays_.empty() && natural_delays_.front().first < now_us - window_us) natural_delays_.pop_front();
}

void AvSync::PictureDisplayed(int64_t capture_us, int64_t render_start_us, int64_t display_us) {
  std::lock_guard<std::mutex> l(mu_);
  const double delay_ms = static_cast<double>(display_us - capture_us) / 1000.0;
  render_ms_.push_back(static_cast<double>(display_us - render_start_us) / 1000.0);
  while (render_ms_.size() > 15) render_ms_.pop_front();
  picture_delays_.emplace_back(display_us, delay_ms);
  last_picture_us_ = std::max(last_picture_us_, display_us);
  double hold_ms = 0;
  if (auto it = holds_.find(capture_us); it != holds_.end()) {
    hold_ms = it->second;
    holds_.erase(it);
  }
  ++n_.pictures;
  if (hold_ms > 0.5) ++n_.pictures_held;
  Keep(&picture_sync_, hold_ms);
  Keep(&picture_delay_, delay_ms);
  const auto timeout_us = static_cast<int64_t>(options_.voice_timeout_ms * 1000.0);
  for (const auto& [id, v] : voices_) {
    if (v.last_playout_us < display_us - timeout_us) continue;
    const double offset = v.delay_ms - delay_ms;
    ++n_.offsets;
    if (offset < -options_.early_limit_ms) ++n_.offsets_early;
    if (offset > options_.late_limit_ms) ++n_.offsets_late;
    Keep(&offsets_, offset);
    Keep(&unsynced_, v.natural_ms - (delay_ms - hold_ms));
    if (options_.keep_trace && trace_.size() < kMaxSamples)
      trace_.push_back({display_us, capture_us, id, delay_ms, hold_ms, v.delay_ms, v.natural_ms, voice_target_ms_, offset});
  }
  if (!options_.hold_pictures) UpdateVoiceTargetLocked(display_us);
  const double natural = VoiceMaxLocked(&Voice::natural_ms, display_us);
  if (natural >= 0) Keep(&voice_sync_, std::max(0.0, voice_target_ms_ - natural));
}

void AvSync::UpdateVoiceTargetLocked(int64_t now_us) {
  TrimWindowsLocked(now_us);
  const auto& window = options_.hold_pictures ? natural_delays_ : picture_delays_;
  if (!options_.enabled || window.empty()) {
    voice_target_ms_ = 0;
    updated_ = false;
    return;
  }
  if (updated_ && now_us - last_update_us_ < static_cast<int64_t>(options_.update_interval_ms * 1000.0)) return;
  updated_ = true;
  last_update_us_ = now_us;
  const std::vector<double> d = SortedDelays(window);
  // Pictures held for their voice: the voice as late as most pictures'
  // natural delays. Else the voice delay that puts the most displayed
  // pictures within the detectability window (voice at most early_limit_ms
  // ahead, late_limit_ms behind), among delays within 35 ms of their median
  // so that the median offset stays small; ties go to the delay nearest the
  // median (with spread delays this leans the voice late: voice ahead of the
  // lips is noticed sooner than voice behind them).
  const double median = d[d.size() / 2];
  double want = median;
  size_t best = 0;
  if (options_.hold_pictures) {
    // Late enough for most pictures; the earlier ones wait for their voice.
    want = UpperQuantile(d, options_.picture_quantile);
  }
  for (double bias = -35.0; bias <= 35.0 && !options_.hold_pictures; bias += 5.0) {
    const double v = median + bias;
    const auto lo = std::lower_bound(d.begin(), d.end(), v - options_.late_limit_ms);
    const auto hi = std::upper_bound(d.begin(), d.end(), v + options_.early_limit_ms);
    const auto covered = static_cast<size_t>(hi - lo);
    if (covered > best || (covered == best && std::abs(bias) < std::abs(want - median))) {
      best = covered;
      want = v;
    }
  }
  const double natural = VoiceMaxLocked(&Voice::natural_ms, now_us);
  if (natural >= 0 && want > natural + options_.max_voice_delay_ms) {
    want = natural + options_.max_voice_delay_ms;
    ++n_.voice_delay_capped;
  } else if (natural < 0) {
    want = std::min(want, options_.max_voice_delay_ms);
  }
  const double base = std::max(natural, 0.0);
  if (std::abs(std::max(want, base) - std::max(voice_target_ms_, base)) > options_.deadband_ms) voice_target_ms_ = want;
}

void AvSync::VoicePlayout(uint32_t stream, int64_t capture_us, int64_t playout_us, double natural_delay_ms) {
  std::lock_guard<std::mutex> l(mu_);
  Voice& v = voices_[stream];
  v.last_playout_us = playout_us;
  v.delay_ms = static_cast<double>(playout_us - capture_us) / 1000.0;
  v.natural_ms = natural_delay_ms;
}

double AvSync::VoiceTargetMs(int64_t now_us) {
  std::lock_guard<std::mutex> l(mu_);
  const auto window_us = static_cast<int64_t>(options_.window_s * 1e6);
  // No picture for a whole window (the site stopped sending them): the voice
  // goes back to its own delay instead of waiting for pictures that do not come.
  if (last_picture_us_ == 0 || last_picture_us_ < now_us - window_us) {
    voice_target_ms_ = 0;
    updated_ = false;
  }
  return options_.enabled ? voice_target_ms_ : 0.0;
}

AvSyncStats AvSync::stats() const {
  std::lock_guard<std::mutex> l(mu_);
  AvSyncStats s = n_;
  s.av_offset_ms_p1 = Quantile(offsets_, 0.01);
  s.av_offset_ms_p50 = Quantile(offsets_, 0.50);
  s.av_offset_ms_p99 = Quantile(offsets_, 0.99);
  s.unsynced_offset_ms_p50 = Quantile(unsynced_, 0.50);
  s.voice_sync_delay_ms = Quantile(voice_sync_, 0.5);
  s.picture_sync_delay_ms = Quantile(picture_sync_, 0.5);
  s.picture_delay_ms = Quantile(picture_delay_, 0.5);
  s.voice_target_ms = options_.enabled ? voice_target_ms_ : 0.0;
  double natural = -1, delay = 0;
  int64_t last = 0;
  for (const auto& [id, v] : voices_) {
    if (v.last_playout_us < last) continue;
    last = v.last_playout_us;
    natural = v.natural_ms;
    delay = v.delay_ms;
  }
  s.voice_natural_ms = std::max(natural, 0.0);
  s.voice_delay_ms = delay;
  return s;
}

std::vector<AvSyncTracePoint> AvSync::trace() const {
  std::lock_guard<std::mutex> l(mu_);
  return trace_;
}

void AvSync::ResetStats() {
  std::lock_guard<std::mutex> l(mu_);
  n_ = AvSyncStats{};
  offsets_.clear();
  unsynced_.clear();
  trace_.clear();
  voice_sync_.clear();
  picture_sync_.clear();
  picture_delay_.clear();
}

}  // namespace holo::audio
