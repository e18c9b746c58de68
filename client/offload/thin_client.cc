#include "client/offload/thin_client.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>
#include <variant>

#include <nlohmann/json.hpp>

#include "client/offload/message_link.h"
#include "client/reproject/fov.h"
#include "client/reproject/rendered_view.h"
#include "common/image_io.h"
#include "net/wire_message.h"

namespace holo::offload {
namespace {

using Clock = std::chrono::steady_clock;

double MsBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

struct Arrived {
  Clock::time_point at;
  protocol::RenderedFrame frame;
  size_t bytes = 0;
  uint32_t stream = 0;
};

pose::PoseSample EyePose(const pose::PoseSample& head, double dx) {
  pose::PoseSample e = head;
  e.position += head.rotation * Eigen::Vector3d(dx, 0, 0);
  return e;
}

}  // namespace

Status ThinClientOptions::Check() const {
  if (port == 0) return InvalidArgument("thin client: no render host port");
  if (width < 16 || height < 16 || width > 4096 || height > 4096) return InvalidArgument("thin client: display size must be 16..4096");
  if (!(hfov_deg > 10 && hfov_deg < 170)) return InvalidArgument("thin client: hfov must be in (10, 170) degrees");
  if (!(rate_hz >= 1 && rate_hz <= 1000)) return InvalidArgument("thin client: rate must be 1..1000 Hz");
  if (frames < 1) return InvalidArgument("thin client: --frames must be >= 1");
  if (trace.size() < 2) return InvalidArgument("thin client: the pose trace has fewer than 2 samples");
  if (!(receive_delay_ms >= 0 && receive_delay_ms <= 5000)) return InvalidArgument("thin client: receive delay must be 0..5000 ms");
  if (!(trace_start_s >= 0)) return InvalidArgument("thin client: trace start must be >= 0");
  if (png_every < 1) return InvalidArgument("thin client: png_every must be >= 1");
  if (!(ipd_m >= 0 && ipd_m <= 0.2)) return InvalidArgument("thin client: --ipd must be in [0, 0.2] m");
  if (!(max_wait_s > 0)) return InvalidArgument("thin client: max_wait_s must be > 0");
  return OkStatus();
}

StatusOr<ThinClientResult> RunThinClient(const ThinClientOptions& o,
                                         const std::function<void(const DisplayedFrame&)>& on_display) {
  HOLO_RETURN_IF_ERROR(o.Check());
  if (!o.out_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(o.out_dir, ec);
    if (ec) return InvalidArgument("thin client: cannot create " + o.out_dir + ": " + ec.message());
  }
  HOLO_ASSIGN_OR_RETURN(std::unique_ptr<MessageLink> link, MessageLink::Connect(o.host, o.port, 5.0));
  protocol::Hello hello;
  hello.role = protocol::Role::kThinClient;
  hello.capabilities.color = {protocol::ColorCodec::kC1};
  hello.access_token = o.token;
  hello.client_name = o.name;
  HOLO_RETURN_IF_ERROR(link->Send(hello));
  HOLO_ASSIGN_OR_RETURN(protocol::Message first, link->Read(5.0));
  if (const auto* r = std::get_if<protocol::Refuse>(&first.payload)) {
    return Unavailable("render host refused: " + r->message);
  }
  if (!std::holds_alternative<protocol::Welcome>(first.payload)) {
    return DataLoss(std::string("render host answered Hello with ") + protocol::MessageTypeName(first.header.type));
  }

  std::mutex mu;
  std::deque<Arrived> arrived;
  Status reader_status;
  std::atomic<bool> stop{false};
  std::atomic<int> received{0};
  std::thread reader([&] {
    while (!stop) {
      auto msg = link->Read(o.max_wait_s);
      if (!msg.ok()) {
        std::lock_guard<std::mutex> lock(mu);
        if (!stop) reader_status = msg.status();
        return;
      }
      if (auto* f = std::get_if<protocol::RenderedFrame>(&msg->payload)) {
        received++;
        std::lock_guard<std::mutex> lock(mu);
        arrived.push_back({Clock::now(), std::move(*f), msg->header.payload_length, msg->header.stream_id});
        while (arrived.size() > 64) arrived.pop_front();
      } else if (auto* ping = std::get_if<protocol::Ping>(&msg->payload)) {
        const int64_t now = net::WallUs();
        (void)link->Send(protocol::Pong{ping->nonce, ping->send_time_us, now, now});
      }
    }
  });
  auto finish = [&]() {
    stop = true;
    link->Close();
    reader.join();
  };

  const reproject::FieldOfView fov = reproject::FieldOfView::FromHorizontalDeg(o.hfov_deg, double(o.width) / o.height);
  CameraModel target;
  target.intrinsics = reproject::IntrinsicsFromFov(fov, o.width, o.height);
  const int64_t trace_t0 = o.trace.front().time_us;
  const int64_t trace_len = std::max<int64_t>(1, o.trace.back().time_us - trace_t0);
  const int64_t start_us = trace_t0 + static_cast<int64_t>(std::llround(o.trace_start_s * 1e6));
  const auto period = std::chrono::microseconds(static_cast<int64_t>(std::llround(1e6 / o.rate_hz)));

  ThinClientResult res;
  std::vector<double> latencies, reproj_ms, borders, bytes;
  DisplayedFrame d;
  bool have_view = false;
  int64_t last_used_frame_seq = -1;
  int64_t frame_seq = 0;
  double latency_ewma = -1;
  reproject::ReprojectOptions ropt;
  ropt.method = o.method;
  reproject::ReprojectOptions stale_opt;
  stale_opt.method = reproject::ReprojectMethod::kNone;
  ImageGray8 valid;
  const auto t_begin = Clock::now();
  auto next_tick = t_begin;
  auto last_image = t_begin;
  auto last_stats = t_begin;
  Clock::time_point first_display{};
  int tick = 0;
  while (res.displayed < o.frames) {
    std::this_thread::sleep_until(next_tick);
    next_tick += period;
    const auto now = Clock::now();
    {
      std::lock_guard<std::mutex> lock(mu);
      if (!reader_status.ok()) {
        Status st = reader_status;
        finish();
        return Unavailable("render host link: " + st.ToString());
      }
    }
    if (MsBetween(last_image, now) > o.max_wait_s * 1e3) {
      finish();
      return Unavailable("thin client: no image from the render host for " + std::to_string(o.max_wait_s) + " s");
    }
    // The pose now (the trace, played in real time, looped), sent at display rate.
    const int64_t clock_us = start_us + std::chrono::duration_cast<std::chrono::microseconds>(now - t_begin).count();
    const int64_t trace_us = trace_t0 + (clock_us - trace_t0) % trace_len;
    pose::PoseSample p = pose::InterpolatePose(o.trace, trace_us);
    p.time_us = clock_us;
    // Headless: an image is "on screen" when it has been reprojected to this
    // tick's pose (no vsync delay modelled), so display time = pose time.
    if (auto st = link->Send(reproject::ToClientPose(p, fov, clock_us)); !st.ok()) {
      finish();
      return st;
    }
    ++tick;
    // The newest frame that has "arrived" (after the simulated delay).
    std::optional<Arrived> take, take_right;
    {
      std::lock_guard<std::mutex> lock(mu);
      const auto due = now - std::chrono::microseconds(static_cast<int64_t>(o.receive_delay_ms * 1e3));
      while (!arrived.empty() && arrived.front().at <= due) {
        Arrived a = std::move(arrived.front());
        arrived.pop_front();
        if (a.stream == 2) {
          if (o.stereo) take_right = std::move(a);  // mono: a stereo host's right eye is not shown
        } else {
          take = std::move(a);
          ++frame_seq;
        }
      }
    }
    if (take_right) {
      if (auto st = reproject::DecodeRenderedFrame(take_right->frame, &d.source_right); !st.ok()) {
        finish();
        return DataLoss("thin client: bad RenderedFrame (right eye) from the render host: " + st.ToString());
      }
      bytes.push_back(static_cast<double>(take_right->bytes));
    }
    if (take) {
      if (auto st = reproject::DecodeRenderedFrame(take->frame, &d.source); !st.ok()) {
        finish();
        return DataLoss("thin client: bad RenderedFrame from the render host: " + st.ToString());
      }
      d.frame_index = take->frame.frame_index;
      d.pose_time_us = take->frame.pose_time_us;
      bytes.push_back(static_cast<double>(take->bytes));
      have_view = true;
      last_image = now;
    }
    if (!have_view) continue;
    // Display: reproject the newest image to the newest pose.
    d.index = res.displayed;
    d.display_us = clock_us;
    d.true_pose = o.stereo ? EyePose(p, -0.5 * o.ipd_m) : p;
    d.true_pose_right = EyePose(p, 0.5 * o.ipd_m);
    target.world_from_camera = d.true_pose.ToPose();
    reproject::ReprojectStats stats;
    const auto r0 = Clock::now();
    const ImageDepth16* depth = d.source.depth.empty() ? nullptr : &d.source.depth;
    if (auto st = reproject::Reproject(d.source.color, depth, d.source.camera, target, ropt, &d.shown, &valid, &stats); !st.ok()) {
      finish();
      return st;
    }
    d.reproject_ms = MsBetween(r0, Clock::now());
    d.black_border_fraction = stats.black_border_fraction;
    if (o.stereo && !d.source_right.color.empty()) {
      CameraModel right = target;
      right.world_from_camera = d.true_pose_right.ToPose();
      const ImageDepth16* rd = d.source_right.depth.empty() ? nullptr : &d.source_right.depth;
      reproject::ReprojectStats s2;
      HOLO_RETURN_IF_ERROR(reproject::Reproject(d.source_right.color, rd, d.source_right.camera, right, ropt, &d.shown_right, &valid, &s2));
    }
    if (o.keep_stale) {
      reproject::ReprojectStats s2;
      HOLO_RETURN_IF_ERROR(reproject::Reproject(d.source.color, depth, d.source.camera, target, stale_opt, &d.stale, &valid, &s2));
    }
    d.pose_to_photon_ms = (clock_us - d.pose_time_us) * 1e-3;  // the truth is the pose at clock_us
    if (res.displayed == 0) first_display = now;
    if (frame_seq != last_used_frame_seq) {
      res.frames_used++;
      last_used_frame_seq = frame_seq;
    }
    latencies.push_back(d.pose_to_photon_ms);
    reproj_ms.push_back(d.reproject_ms);
    borders.push_back(d.black_border_fraction);
    latency_ewma = latency_ewma < 0 ? d.pose_to_photon_ms : 0.9 * latency_ewma + 0.1 * d.pose_to_photon_ms;
    if (on_display) on_display(d);
    if (!o.out_dir.empty() && res.displayed % o.png_every == 0) {
      char name[64];
      std::snprintf(name, sizeof(name), "/frame_%05d.png", res.displayed);
      if (o.stereo && d.shown_right.width() == d.shown.width()) {
        ImageRgb8 both(2 * o.width, o.height);
        for (int y = 0; y < o.height; ++y) {
          std::copy_n(d.shown.data() + size_t(y) * o.width * 3, o.width * 3, both.data() + size_t(y) * 2 * o.width * 3);
          std::copy_n(d.shown_right.data() + size_t(y) * o.width * 3, o.width * 3,
                      both.data() + (size_t(y) * 2 * o.width + o.width) * 3);
        }
        HOLO_RETURN_IF_ERROR(WriteImageRgb8(o.out_dir + name, both));
      } else {
        HOLO_RETURN_IF_ERROR(WriteImageRgb8(o.out_dir + name, d.shown));
      }
    }
    res.displayed++;
    // Tell the host the measured pose→photon latency (its prediction horizon).
    if (MsBetween(last_stats, now) > 250) {
      last_stats = now;
      protocol::Stats s;
      s.values.push_back({"pose_to_photon_ms", latency_ewma});
      (void)link->Send(s);
    }
  }
  const auto t_end = Clock::now();
  res.bytes_received = link->bytes_received();
  finish();
  res.frames_received = received;
  res.duration_s = MsBetween(t_begin, t_end) * 1e-3;
  const double shown_s = std::max(1e-3, MsBetween(first_display, t_end) * 1e-3);
  res.fps = res.displayed / shown_s;
  res.received_fps = res.frames_used / shown_s;
  auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
  };
  res.mean_pose_to_photon_ms = mean(latencies);
  std::vector<double> sorted = latencies;
  std::sort(sorted.begin(), sorted.end());
  res.p95_pose_to_photon_ms = sorted.empty() ? 0 : sorted[std::min(sorted.size() - 1, sorted.size() * 95 / 100)];
  res.mean_reproject_ms = mean(reproj_ms);
  res.mean_black_border = mean(borders);
  res.mean_frame_bytes = mean(bytes);
  if (!o.out_dir.empty()) {
    nlohmann::json j = {{"displayed", res.displayed},
                        {"fps", res.fps},
                        {"frames_received", res.frames_received},
                        {"frames_used", res.frames_used},
                        {"received_fps", res.received_fps},
                        {"pose_to_photon_ms_mean", res.mean_pose_to_photon_ms},
                        {"pose_to_photon_ms_p95", res.p95_pose_to_photon_ms},
                        {"reproject_ms_mean", res.mean_reproject_ms},
                        {"black_border_fraction_mean", res.mean_black_border},
                        {"frame_bytes_mean", res.mean_frame_bytes},
                        {"bytes_received", res.bytes_received},
                        {"receive_delay_ms", o.receive_delay_ms},
                        {"size", std::to_string(o.width) + "x" + std::to_string(o.height)},
                        {"method", reproject::ReprojectMethodName(o.method)},
                        {"stereo", o.stereo},
                        {"duration_s", res.duration_s}};
    std::ofstream f(o.out_dir + "/stats.json");
    f << j.dump(2) << "\n";
    if (!f) return Unavailable("thin client: cannot write " + o.out_dir + "/stats.json");
  }
  return res;
}

}  // namespace holo::offload
