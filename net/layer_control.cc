#include "net/layer_control.h"

#include <algorithm>
#include <cmath>

namespace holo::net {

namespace {
constexpr double kUs = 1e-6;
}  // namespace

Status LayerPolicy::Check() const {
  auto bad = [](const char* key, const char* range, double v) {
    return InvalidArgument(std::string("layers.") + key + " must be " + range + ", got " + std::to_string(v));
  };
  if (!(down_queue_s > 0 && down_queue_s <= 60)) return bad("down_queue_s", "in (0, 60] s", down_queue_s);
  if (!(kernel_backlog_s > 0 && kernel_backlog_s <= 60))
    return bad("kernel_backlog_s", "in (0, 60] s", kernel_backlog_s);
  if (!(throughput_window_s > 0 && throughput_window_s <= 60))
    return bad("throughput_window_s", "in (0, 60] s", throughput_window_s);
  if (!(busy_fraction > 0 && busy_fraction <= 1)) return bad("busy_fraction", "in (0, 1]", busy_fraction);
  if (!(down_throughput > 0 && down_throughput <= 1)) return bad("down_throughput", "in (0, 1]", down_throughput);
  if (!(up_hold_s > 0 && up_hold_s <= 600)) return bad("up_hold_s", "in (0, 600] s", up_hold_s);
  if (!(max_up_hold_s >= up_hold_s && max_up_hold_s <= 3600))
    return bad("max_up_hold_s", ">= up_hold_s and <= 3600 s", max_up_hold_s);
  if (!(up_headroom >= 1 && up_headroom <= 10)) return bad("up_headroom", "in [1, 10]", up_headroom);
  if (!(stable_s > 0 && stable_s <= 3600)) return bad("stable_s", "in (0, 3600] s", stable_s);
  if (!(probe_s >= 0 && probe_s <= 60)) return bad("probe_s", "in [0, 60] s", probe_s);
  return OkStatus();
}

LayerController::LayerController(LayerPolicy policy) : p_(policy), hold_s_(policy.up_hold_s) {}

void LayerController::SetNumLayers(int n) {
  num_layers_ = std::clamp(n, 1, kMaxLayers);
  min_layer_ = std::min(min_layer_, num_layers_ - 1);
  layer_ = std::min(layer_, num_layers_ - 1);
  target_ = std::min(target_, num_layers_ - 1);
}

int LayerController::MinLayerForQuality(int quality, int num_layers) {
  const int q = std::clamp(quality, 0, 10);
  const int n = std::clamp(num_layers, 1, kMaxLayers);
  return std::min(n - 1, (10 - q) * n / 11);
}

void LayerController::SetMinLayer(int min_layer, int64_t now_us) {
  min_layer_ = std::clamp(min_layer, 0, num_layers_ - 1);
  if (target_ < min_layer_) SetTarget(min_layer_, now_us, "quality");
}

void LayerController::Decay(int64_t now_us) {
  if (decay_us_ >= 0 && now_us > decay_us_) {
    const double f = std::exp(-static_cast<double>(now_us - decay_us_) * kUs / p_.throughput_window_s);
    sum_bytes_ *= f;
    sum_busy_s_ *= f;
  }
  if (now_us > decay_us_) decay_us_ = now_us;
}

void LayerController::OnEnqueue(int64_t now_us, size_t queue_depth, bool dropped) {
  if (dropped) drop_pending_ = true;
  queue_depth_ = queue_depth;
  NoteBacklog(now_us, queue_depth >= 2 || kernel_backlog_);
}

void LayerController::NoteBacklog(int64_t now_us, bool high) {
  if (high) {
    if (queue_high_since_us_ < 0) queue_high_since_us_ = now_us;
    queue_high_last_us_ = now_us;
  } else {
    queue_high_since_us_ = -1;
  }
}

void LayerController::OnWrite(int64_t now_us, size_t bytes, int64_t write_us, size_t unsent_bytes) {
  Decay(now_us);
  unsent_bytes_ = unsent_bytes;
  sum_bytes_ += static_cast<double>(bytes);
  sum_busy_s_ += static_cast<double>(std::max<int64_t>(write_us, 1)) * kUs;
}

double LayerController::throughput_bytes_per_s() const {
  return sum_busy_s_ > 0 ? sum_bytes_ / sum_busy_s_ : -1.0;
}

void LayerController::SetTarget(int t, int64_t now_us, const char* why) {
  if (t == target_) return;
  if (t < target_) last_up_us_ = now_us;
  target_ = t;
  target_since_us_ = now_us;
  reason_ = why;
}

void LayerController::Update(int64_t now_us, std::span<const double> rates) {
  Decay(now_us);
  auto rate = [&](int layer) { return layer >= 0 && static_cast<size_t>(layer) < rates.size() ? rates[layer] : 0.0; };
  // The kernel's unsent bytes as time at this layer's bitrate.
  const double r = rate(layer_);
  kernel_backlog_ = r > 0 && static_cast<double>(unsent_bytes_) / r > p_.kernel_backlog_s;
  NoteBacklog(now_us, queue_depth_ >= 2 || kernel_backlog_);
  if (target_ < min_layer_) SetTarget(min_layer_, now_us, "quality");
  if (!p_.adaptive) {
    if (target_ != min_layer_) SetTarget(min_layer_, now_us, "quality");
    drop_pending_ = false;
    return;
  }
  if (target_ != layer_) {  // a switch is waiting for its independent frame
    drop_pending_ = false;
    return;
  }
  const int l = layer_;
  if (l + 1 < num_layers_) {
    const char* why = nullptr;
    const double busy = sum_busy_s_ / p_.throughput_window_s;
    const bool probing = last_up_us_ >= 0 && (now_us - last_up_us_) * kUs < p_.probe_s;
    if (drop_pending_) {
      why = "drop";
    } else if (probing && queue_high_since_us_ >= 0) {
      why = "probe failed";
    } else if (queue_high_since_us_ >= 0 && (now_us - queue_high_since_us_) * kUs >= p_.down_queue_s) {
      why = kernel_backlog_ && queue_depth_ < 2 ? "socket backlog" : "queue";
    } else if (busy >= p_.busy_fraction && rate(l) > 0 && throughput_bytes_per_s() < p_.down_throughput * rate(l)) {
      why = "throughput";
    }
    if (why != nullptr) {
      // Back down soon after a probe up: the upper layer does not fit; wait longer next time.
      if (last_up_us_ >= 0 && (now_us - last_up_us_) * kUs < p_.stable_s)
        hold_s_ = std::min(2 * hold_s_, p_.max_up_hold_s);
      SetTarget(l + 1, now_us, why);
      drop_pending_ = false;
      queue_high_since_us_ = -1;
      return;
    }
  }
  drop_pending_ = false;
  const double on_layer_s = (now_us - target_since_us_) * kUs;
  if (on_layer_s >= p_.stable_s) hold_s_ = p_.up_hold_s;
  if (l > min_layer_ && on_layer_s >= hold_s_) {
    const bool calm = queue_high_since_us_ < 0 &&
                      (queue_high_last_us_ < 0 || (now_us - queue_high_last_us_) * kUs >= hold_s_);
    const double tp = throughput_bytes_per_s();
    const double need = p_.up_headroom * rate(l - 1);
    if (calm && (tp < 0 || need <= 0 || tp >= need)) SetTarget(l - 1, now_us, "probe");
  }
}

bool LayerController::Take(int layer, bool independent, bool* switched) {
  if (switched != nullptr) *switched = false;
  if (layer == target_ && target_ != layer_ && independent) {
    if (target_ > layer_) ++switches_down_;
    layer_ = target_;
    ++switches_;
    // The old layer's queue state says nothing about the new one.
    queue_high_since_us_ = -1;
    queue_depth_ = 0;
    unsent_bytes_ = 0;
    if (switched != nullptr) *switched = true;
    return true;
  }
  return layer == layer_;
}

}  // namespace holo::net
