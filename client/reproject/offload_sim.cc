#include "client/reproject/offload_sim.h"
#include "common/clock.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <map>
#include <memory>
#include <variant>

#include "common/image_io.h"
#include "common/metrics/image_metrics.h"
#include "common/quantile.h"
#include "protocol/messages.h"

namespace holo::reproject {
namespace {

double MeanOf(const std::vector<double>& v) {
  if (v.empty()) return 0;
  double s = 0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

}  // namespace

const char* OffloadModeName(OffloadMode m) {
  switch (m) {
    case OffloadMode::kIdeal: return "ideal";
    case OffloadMode::kStale: return "stale";
    case OffloadMode::kReprojected: return "reprojected";
    case OffloadMode::kPredicted: return "predicted";
    case OffloadMode::kEnlarged: return "enlarged";
  }
  return "?";
}

Status OffloadSimOptions::Check() const {
  if (width < 16 || height < 16 || width > 4096 || height > 4096) {
    return InvalidArgument("display size must be 16..4096 per side, got " + std::to_string(width) + "x" +
                           std::to_string(height));
  }
  if (!(hfov_deg > 10 && hfov_deg < 170)) return InvalidArgument("hfov_deg must be in (10, 170)");
  if (!(margin >= 0 && margin <= 2)) return InvalidArgument("margin must be in [0, 2]");
  if (latencies_ms.empty()) return InvalidArgument("no latency to simulate");
  for (int l : latencies_ms) {
    if (l < 0 || l > 1000) return InvalidArgument("latencies must be in 0..1000 ms, got " + std::to_string(l));
  }
  if (display_frames < 1) return InvalidArgument("display_frames must be >= 1");
  if (!(warmup_s >= 0)) return InvalidArgument("warmup_s must be >= 0");
  if (!(content_fps > 0)) return InvalidArgument("content_fps must be > 0");
  if (modes.empty()) return InvalidArgument("no mode to simulate");
  if (png_every < 1) return InvalidArgument("png_every must be >= 1");
  return predictor_options.Check();
}

StatusOr<std::vector<OffloadResult>> SimulateOffload(const std::vector<pose::PoseSample>& trace,
                                                     const SceneAtFrame& scene, const OffloadSimOptions& o,
                                                     const std::function<void(int, int)>& progress) {
  HOLO_RETURN_IF_ERROR(o.Check());
  if (trace.size() < 2) return InvalidArgument("SimulateOffload: trace has fewer than 2 samples");
  const int64_t t_begin = trace.front().time_us + std::llround(o.warmup_s * 1e6);
  const int64_t t_end = trace.back().time_us;
  if (t_end - t_begin < 100000) return InvalidArgument("SimulateOffload: trace shorter than warm-up + 0.1 s");
  const int64_t step = o.display_frames > 1 ? (t_end - t_begin) / (o.display_frames - 1) : 0;

  const FieldOfView display_fov = FieldOfView::FromHorizontalDeg(o.hfov_deg, static_cast<double>(o.width) / o.height);
  const FieldOfView big_fov = display_fov.Enlarged(o.margin);
  const std::array<int, 2> big_size = ResolutionForFov(display_fov, o.width, o.height, big_fov);
  const size_t num_lat = o.latencies_ms.size();

  std::vector<std::unique_ptr<pose::PosePredictor>> predictors;
  for (size_t k = 0; k < num_lat; ++k) {
    HOLO_ASSIGN_OR_RETURN(std::unique_ptr<pose::PosePredictor> p, pose::MakePredictor(o.predictor, o.predictor_options));
    predictors.push_back(std::move(p));
  }
  std::vector<size_t> fed(num_lat, 0);
  struct Acc {
    std::vector<double> psnr, psnr_content, border, holes, bytes, cpu_ms;
  };
  std::vector<Acc> acc(num_lat * o.modes.size());

  RenderedView truth, host, received;
  ImageRgb8 shown;
  ImageGray8 valid, content;
  ReprojectOptions ropt;
  ropt.filter = o.filter;
  for (int f = 0; f < o.display_frames; ++f) {
    const int64_t t_d = t_begin + f * step;
    const int64_t frame = static_cast<int64_t>(std::floor(t_d * 1e-6 * o.content_fps));
    const SceneRenderFn render = scene(frame);
    const pose::PoseSample display_pose = pose::InterpolatePose(trace, t_d);
    HOLO_RETURN_IF_ERROR(RenderAtPose(render, display_pose.ToPose(), display_fov, o.width, o.height, &truth));
    CameraModel target = truth.camera;
    const bool png = !o.png_dir.empty() && f % o.png_every == 0;
    const std::string png_base = o.png_dir + "/f" + std::to_string(f);
    if (png) HOLO_RETURN_IF_ERROR(WriteImageRgb8(png_base + "_truth.png", truth.color));
    for (size_t k = 0; k < num_lat; ++k) {
      const int64_t latency_us = int64_t{o.latencies_ms[k]} * 1000;
      // The newest tracker sample the host has: sampled at or before t_d − L.
      while (fed[k] < trace.size() && trace[fed[k]].time_us <= t_d - latency_us) {
        predictors[k]->Observe(trace[fed[k]++]);
      }
      if (fed[k] == 0) continue;
      const pose::PoseSample sent = trace[fed[k] - 1];
      const pose::PoseSample predicted = predictors[k]->Predict(sent.time_us + latency_us);
      std::map<int, size_t> wire_bytes_of;  // host image id → bytes
      int current_image = -1;
      for (size_t m = 0; m < o.modes.size(); ++m) {
        const OffloadMode mode = o.modes[m];
        // stale and reprojected show the same host image (id 1).
        const int image_id = mode == OffloadMode::kIdeal         ? 0
                             : mode == OffloadMode::kStale || mode == OffloadMode::kReprojected ? 1
                             : mode == OffloadMode::kPredicted    ? 2
                                                                  : 3;
        if (image_id != current_image) {
          const pose::PoseSample& at = image_id == 0 ? display_pose : image_id == 1 ? sent : predicted;
          const bool big = image_id == 3;
          HOLO_RETURN_IF_ERROR(RenderAtPose(render, at.ToPose(), big ? big_fov : display_fov,
                                            big ? big_size[0] : o.width, big ? big_size[1] : o.height, &host));
          host.frame_index = frame;
          host.pose_time_us = sent.time_us;
          HOLO_ASSIGN_OR_RETURN(protocol::RenderedFrame wire, EncodeRenderedView(host, o.encode));
          const std::vector<uint8_t> bytes = protocol::EncodePayload(wire);
          HOLO_ASSIGN_OR_RETURN(protocol::Payload payload,
                                protocol::DecodePayload(protocol::MessageType::kRenderedFrame, bytes));
          HOLO_RETURN_IF_ERROR(DecodeRenderedFrame(std::get<protocol::RenderedFrame>(payload), &received));
          wire_bytes_of[image_id] = bytes.size();
          current_image = image_id;
        }
        ropt.method = mode == OffloadMode::kIdeal || mode == OffloadMode::kStale ? ReprojectMethod::kNone : o.method;
        ReprojectStats stats;
        const double cpu0 = holo::ThreadCpuTimeMs();
        HOLO_RETURN_IF_ERROR(Reproject(received.color, &received.depth, received.camera, target, ropt, &shown, &valid, &stats));
        const double cpu1 = holo::ThreadCpuTimeMs();
        content.Resize(o.width, o.height);
        for (size_t i = 0; i < content.num_pixels(); ++i) {
          const uint8_t* c = shown.data() + 3 * i;
          const uint8_t* t = truth.color.data() + 3 * i;
          content.data()[i] = (c[0] | c[1] | c[2] | t[0] | t[1] | t[2]) ? 255 : 0;
        }
        HOLO_ASSIGN_OR_RETURN(double psnr, metrics::ComputePsnr(shown, truth.color));
        HOLO_ASSIGN_OR_RETURN(double psnr_content, metrics::ComputePsnr(shown, truth.color, &content));
        Acc& a = acc[k * o.modes.size() + m];
        a.psnr.push_back(psnr);
        a.psnr_content.push_back(psnr_content);
        a.border.push_back(stats.black_border_fraction);
        a.holes.push_back(stats.hole_fraction);
        a.bytes.push_back(static_cast<double>(wire_bytes_of[image_id]));
        a.cpu_ms.push_back(cpu1 - cpu0);
        if (png) {
          HOLO_RETURN_IF_ERROR(WriteImageRgb8(
              png_base + "_L" + std::to_string(o.latencies_ms[k]) + "_" + OffloadModeName(mode) + ".png", shown));
        }
      }
    }
    if (progress) progress(f + 1, o.display_frames);
  }
  std::vector<OffloadResult> results;
  for (size_t k = 0; k < num_lat; ++k) {
    for (size_t m = 0; m < o.modes.size(); ++m) {
      const Acc& a = acc[k * o.modes.size() + m];
      OffloadResult r;
      r.latency_ms = o.latencies_ms[k];
      r.mode = o.modes[m];
      r.frames = static_cast<int>(a.psnr.size());
      r.psnr_db = MeanOf(a.psnr);
      r.psnr_content_db = MeanOf(a.psnr_content);
      r.black_border_fraction = MeanOf(a.border);
      r.hole_fraction = MeanOf(a.holes);
      r.wire_bytes = MeanOf(a.bytes);
      r.reproject_cpu_ms = Quantile(a.cpu_ms, 0.5);
      r.frame_psnr_db = a.psnr;
      results.push_back(r);
    }
  }
  return results;
}

}  // namespace holo::reproject
