#include "server/pods/pod_runner.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/clock.h"
#include "net/wire_message.h"
#include "common/log.h"
#include "protocol/color_codec.h"
#include "protocol/depth_codec.h"
#include "server/capture/dataset.h"
#include "server/capture/prerendered.h"
#include "server/pods/pod_client.h"
#include "server/pods/socket_io.h"
#include "server/stereo/stereo_depth.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::pods {

Status PodRunOptions::Check() const {
  if (token.empty()) return InvalidArgument("--token is required (the site's pod token)");
  if (pod_id < 0) return InvalidArgument("--pod is required (this pod's id in the rig, >= 0)");
  if (!(fps > 0 && fps <= 240)) return InvalidArgument("--fps must be in (0, 240], got " + std::to_string(fps));
  if (prerender < 0) return InvalidArgument("--prerender must be >= 0");
  if (jpeg_quality < 1 || jpeg_quality > 100) return InvalidArgument("--jpeg-quality must be in 1..100");
  if (queue_frames < 1) return InvalidArgument("--queue must be >= 1");
  if (depth_codec != "d1" && depth_codec != "d2")
    return InvalidArgument("--depth-codec must be d1 or d2, got '" + depth_codec + "'");
  if (depth != "direct" && depth != "stereo")
    return InvalidArgument("--depth must be direct or stereo, got '" + depth + "'");
  // A dataset's frames carry their depth already (and no IR pairs to match).
  if (depth == "stereo" && !dataset.empty())
    return InvalidArgument("--depth stereo needs the synthetic studio (its IR pairs); a --dataset already has depth: "
                           "drop one of the two");
  if (stereo_threads < 0 || stereo_threads > 256) return InvalidArgument("--stereo-threads must be in 0..256");
  if (stereo_roi != "on" && stereo_roi != "off")
    return InvalidArgument("--stereo-roi must be on or off, got '" + stereo_roi + "'");
  if (stereo_search != "sgbm" && stereo_search != "patchmatch")
    return InvalidArgument("--stereo-search must be sgbm or patchmatch, got '" + stereo_search + "'");
  if (stereo_temporal != "on" && stereo_temporal != "off")
    return InvalidArgument("--stereo-temporal must be on or off, got '" + stereo_temporal + "'");
  if (!(stereo_still >= 0 && stereo_still <= 100))
    return InvalidArgument("--stereo-still must be in [0, 100], got " + FormatNumber(stereo_still));
  if (stereo_dense_pass != "on" && stereo_dense_pass != "off")
    return InvalidArgument("--stereo-dense-pass must be on or off, got '" + stereo_dense_pass + "'");
  if (std::abs(clock_drift_ppm) > 1000) return InvalidArgument("--clock-drift-ppm must be within ±1000");
  std::string host;
  uint16_t port = 0;
  HOLO_RETURN_IF_ERROR(ParseHostPort(site, &host, &port).WithContext("--site"));
  if (port == 0) return InvalidArgument("--site: port must be 1..65535");
  return OkStatus();
}

namespace {

// The studio's view of this pod. With stereo parts set, each frame's depth is
// replaced by PatchMatch depth from the pod's IR pair (the colour stays the
// studio's, as a stereo pod's colour camera is the same camera).
class StudioFrames final : public PodFrames {
 public:
  struct Stereo {
    std::unique_ptr<StereoStudioRenderer> renderer;  // renders this pod's pair only
    std::unique_ptr<PatchMatchStereo> matcher;
    std::unique_ptr<StereoRoiPolicy> roi;  // where to match (disabled: the whole pair)
    float far_m = 0;  // depth beyond is dropped (the server's StereoDepthOptions)
  };
  StudioFrames(std::unique_ptr<SyntheticStudio> studio, int pod_index, const PodCalibration& calibration, Stereo stereo)
      : studio_(std::move(studio)), pod_index_(pod_index), stereo_(std::move(stereo)) {
    calibration_ = calibration;
  }
  // Renders (and matches) the first `count` frames; Get loops them.
  Status Prerender(int count) {
    loop_.resize(static_cast<size_t>(count));
    for (int k = 0; k < count; ++k) HOLO_RETURN_IF_ERROR(Render(k, &loop_[static_cast<size_t>(k)]));
    return OkStatus();
  }
  Status Get(int64_t slot, RgbdFrame* out) override {
    if (!loop_.empty()) {
      *out = loop_[static_cast<size_t>(LoopContent(slot, static_cast<int64_t>(loop_.size())))];
      return OkStatus();
    }
    // Live rendering: the studio's animation repeats every 2 minutes of slots.
    return Render(slot % 3600, out);
  }

 private:
  Status Render(int64_t frame_index, RgbdFrame* out) {
    studio_->RenderPod(frame_index, pod_index_, out);
    if (!stereo_.renderer) return OkStatus();
    stereo_.renderer->RenderPod(frame_index, pod_index_, &pair_);
    // Frames come in order (pre-rendered 0, 1, ...; live by slot, skipped
    // slots making a gap the region's margin grows with): the previous
    // frame's foreground gives the region.
    HOLO_RETURN_IF_ERROR(
        stereo_.roi->Match(stereo_.matcher.get(), frame_index, pair_.left, pair_.right, &disparity_).status());
    return DisparityToDepth(stereo_.renderer->rig().pods[static_cast<size_t>(pod_index_)], disparity_, stereo_.far_m,
                            &out->depth);
  }

  std::unique_ptr<SyntheticStudio> studio_;
  int pod_index_;
  Stereo stereo_;
  StereoPair pair_;
  ImageFloat disparity_;
  std::vector<RgbdFrame> loop_;
};

class DatasetFrames final : public PodFrames {
 public:
  DatasetFrames(std::unique_ptr<DatasetReader> reader, size_t index) : reader_(std::move(reader)), index_(index) {
    calibration_ = reader_->rig().pods[index_];
  }
  Status Get(int64_t, RgbdFrame* out) override {
    Status s = reader_->Next(&set_);
    if (s.code() == StatusCode::kOutOfRange) {  // loop the recording
      HOLO_RETURN_IF_ERROR(reader_->Seek(0));
      s = reader_->Next(&set_);
    }
    HOLO_RETURN_IF_ERROR(s);
    *out = std::move(set_.frames[index_]);
    return OkStatus();
  }

 private:
  std::unique_ptr<DatasetReader> reader_;
  size_t index_;
  RgbdFrameSet set_;
};

Status FindPod(const Rig& rig, int pod_id, size_t* index) {
  for (size_t i = 0; i < rig.pods.size(); ++i)
    if (rig.pods[i].id == pod_id) {
      *index = i;
      return OkStatus();
    }
  return InvalidArgument("--pod " + std::to_string(pod_id) + " is not in rig '" + rig.name + "'");
}

}  // namespace

StatusOr<std::unique_ptr<PodFrames>> OpenPodFrames(const PodRunOptions& o,
                                                   const std::function<void(const std::string&)>& log) {
  HOLO_RETURN_IF_ERROR(o.Check());
  auto say = [&](const std::string& s) {
    if (log) log(s);
  };
  if (!o.dataset.empty()) {
    HOLO_ASSIGN_OR_RETURN(auto reader, DatasetReader::Open(o.dataset));
    size_t index = 0;
    HOLO_RETURN_IF_ERROR(FindPod(reader->rig(), o.pod_id, &index));
    return std::unique_ptr<PodFrames>(std::make_unique<DatasetFrames>(std::move(reader), index));
  }
  HOLO_ASSIGN_OR_RETURN(Workload w, GetWorkload(o.workload));
  Rig rig = w.rig;
  if (!o.rig_path.empty()) {
    HOLO_ASSIGN_OR_RETURN(rig, LoadRig(o.rig_path));
  }
  size_t index = 0;
  HOLO_RETURN_IF_ERROR(FindPod(rig, o.pod_id, &index));
  StudioOptions so = w.studio;
  so.threads = 1;  // one pod per process: eight of them share the machine
  HOLO_ASSIGN_OR_RETURN(auto studio, SyntheticStudio::Create(rig, so));
  StudioFrames::Stereo stereo;
  if (o.depth == "stereo") {
    // As holoport-server --depth stereo: the server's default stereo options
    // and the default stereo block where the rig has none. The depth lands in
    // the pod's depth camera, so the calibration the pod sends (depth and
    // colour cameras, poses) is the one the site's rig holds, stereo or not.
    StereoDepthOptions sd;
    HOLO_ASSIGN_OR_RETURN(stereo.renderer,
                          StereoStudioRenderer::Create(studio.get(), WithStereoPods(studio->rig()), sd.render));
    PatchMatchOptions pm = sd.patchmatch;
    StereoSearchRange(stereo.renderer->rig().pods[index], sd.near_m, sd.far_m, &pm);
    pm.threads = o.stereo_threads;
    pm.temporal = o.stereo_temporal == "on";
    pm.temporal_still = static_cast<float>(o.stereo_still);
    if (o.stereo_dense_pass == "off") pm.final_window_step = 0;
    HOLO_ASSIGN_OR_RETURN(stereo.matcher, PatchMatchStereo::Create(pm));
    stereo.far_m = sd.far_m;
    StereoRoiOptions roi = sd.roi;
    roi.enabled = o.stereo_roi == "on";
    roi.search_with_sgbm = o.stereo_search == "sgbm";
    roi.fps = so.fps;
    // The rig's pods take turns for their periodic full match (as in the site's stereo source).
    roi.full_phase = StereoRoiPolicy::FullPhase(index, rig.pods.size(), roi.full_every);
    HOLO_RETURN_IF_ERROR(roi.Check().WithContext("stereo region options"));
    stereo.roi = std::make_unique<StereoRoiPolicy>(stereo.renderer->rig().pods[index], roi);
  }
  auto frames = std::make_unique<StudioFrames>(std::move(studio), static_cast<int>(index), rig.pods[index],
                                               std::move(stereo));
  if (o.prerender > 0) {
    say("pre-rendering " + std::to_string(o.prerender) + " frames of " + w.name +
        (o.depth == "stereo" ? " with stereo depth (IR rendering and PatchMatch: ~0.1 s per QVGA frame and core)" : ""));
    HOLO_RETURN_IF_ERROR(frames->Prerender(o.prerender));
  }
  return std::unique_ptr<PodFrames>(std::move(frames));
}

Status RunPod(const PodRunOptions& o, const std::atomic<bool>& stop) {
  HOLO_RETURN_IF_ERROR(o.Check());
  auto say = [&](const std::string& s) {
    if (!o.quiet) spdlog::info("holoport-pod {}: {}", o.pod_id, s);
  };
  // This pod's calibration and frame producer.
  HOLO_ASSIGN_OR_RETURN(std::unique_ptr<PodFrames> frames, OpenPodFrames(o, say));
  const PodCalibration calibration = frames->calibration();
  if (o.depth == "stereo" && o.prerender == 0)
    say("stereo depth live: IR rendering and PatchMatch take ~0.1 s per QVGA frame and core, slots in between are skipped "
        "(--prerender N matches N frames first and loops them)");

  // The pod's clock: the system clock plus the simulated offset and drift.
  const int64_t t_start = net::WallUs();
  const auto offset_us = static_cast<int64_t>(std::llround(o.clock_offset_ms * 1000.0));
  const double drift = o.clock_drift_ppm * 1e-6;
  auto pod_clock_at = [=](int64_t wall) {
    return wall + offset_us + static_cast<int64_t>(std::llround(static_cast<double>(wall - t_start) * drift));
  };

  PodClientOptions co;
  HOLO_RETURN_IF_ERROR(ParseHostPort(o.site, &co.host, &co.port));
  if (co.host.empty()) co.host = "127.0.0.1";
  co.token = o.token;
  co.name = "pod-" + std::to_string(o.pod_id);
  co.calibration = calibration;
  co.queue_frames = static_cast<size_t>(o.queue_frames);
  co.clock = [=] { return pod_clock_at(net::WallUs()); };
  co.log = [&](const std::string& s) { say(s); };
  PodClient client(co);
  HOLO_RETURN_IF_ERROR(client.Start());

  FILE* stats = nullptr;
  if (!o.stats_path.empty()) {
    stats = o.stats_path == "-" ? stdout : std::fopen(o.stats_path.c_str(), "w");
    if (!stats) return Unavailable(o.stats_path + ": cannot open for writing");
  }
  protocol::ColorEncodeOptions copt;
  copt.jpeg_quality = o.jpeg_quality;
  protocol::ColorEncoder color_encoder(copt);
  protocol::DepthEncodeOptions dopt;
  dopt.codec = o.depth_codec == "d1" ? protocol::DepthCodec::kD1 : protocol::DepthCodec::kD2;
  dopt.zstd_level = o.zstd_level;
  const ImageGray8 no_mask;  // the whole image: the site segments

  const double period_us = 1e6 / o.fps;
  int64_t slot = static_cast<int64_t>(std::ceil(static_cast<double>(net::WallUs()) / period_us));
  int64_t number = 0, skipped = 0, done = 0;
  double encode_cpu_ms = 0, produce_cpu_ms = 0;
  uint64_t depth_bytes = 0, color_bytes = 0;
  int64_t next_stats = net::WallUs() + 1000000;
  RgbdFrame frame;
  say("streaming pod " + std::to_string(o.pod_id) + " to " + o.site + " at " + std::to_string(o.fps) + " fps");
  Status result;
  while (!stop && (o.frames < 0 || done < o.frames)) {
    const Status cs = client.status();
    if (!cs.ok()) {
      result = cs;
      break;
    }
    const auto slot_wall = static_cast<int64_t>(std::llround(static_cast<double>(slot) * period_us));
    const int64_t now = net::WallUs();
    if (now < slot_wall) {
      std::this_thread::sleep_for(std::chrono::microseconds(std::min<int64_t>(slot_wall - now, 50000)));
      continue;
    }
    if (now > slot_wall + static_cast<int64_t>(period_us)) {
      // Missed whole slots (the pod was too slow): take the current one, as a camera drops frames.
      const auto current = static_cast<int64_t>(std::floor(static_cast<double>(now) / period_us));
      skipped += current - slot;
      slot = current;
      continue;
    }
    double c0 = ThreadCpuTimeMs();
    HOLO_RETURN_IF_ERROR(frames->Get(slot, &frame));
    const double c1 = ThreadCpuTimeMs();
    protocol::PodFrame pf;
    pf.pod_id = static_cast<uint16_t>(o.pod_id);
    pf.frame_number = number++;
    pf.capture_time_us = pod_clock_at(slot_wall);  // the trigger instant on the pod's clock
    pf.depth_codec = dopt.codec;
    HOLO_RETURN_IF_ERROR(protocol::EncodeDepth(frame.depth, dopt, &pf.depth));
    HOLO_RETURN_IF_ERROR(color_encoder.Encode(frame.color, no_mask, &pf.color));
    encode_cpu_ms += ThreadCpuTimeMs() - c1;
    depth_bytes += pf.depth.size();
    color_bytes += pf.color.size();
    produce_cpu_ms += c1 - c0;
    client.Offer(std::move(pf));
    ++done;
    ++slot;
    if (net::WallUs() >= next_stats || (o.frames >= 0 && done == o.frames)) {
      next_stats += 1000000;
      const PodClientCounters c = client.counters();
      if (stats) {
        // One JSON line per second; CPU times rounded to 0.1 ms.
        nlohmann::ordered_json j;
        j["pod"] = o.pod_id;
        j["frames"] = done;
        j["skipped"] = skipped;
        j["sent"] = c.sent;
        j["bytes_sent"] = c.bytes_sent;
        j["dropped_queue_full"] = c.dropped_queue_full;
        j["dropped_disconnected"] = c.dropped_disconnected;
        j["connects"] = c.connects;
        j["connected"] = c.connected;
        j["encode_cpu_ms"] = std::round(encode_cpu_ms * 10) / 10;
        j["produce_cpu_ms"] = std::round(produce_cpu_ms * 10) / 10;
        j["depth_bytes"] = depth_bytes;
        j["color_bytes"] = color_bytes;
        j["depth_codec"] = o.depth_codec;
        j["depth"] = o.depth;
        std::fprintf(stats, "%s\n", j.dump().c_str());
        std::fflush(stats);
      }
    }
  }
  // Let the last frames leave.
  for (int i = 0; i < 50 && client.connected(); ++i) {
    const PodClientCounters c = client.counters();
    if (c.sent + c.dropped_queue_full + c.dropped_disconnected >= c.offered) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  client.Stop();
  if (stats && stats != stdout) std::fclose(stats);
  if (result.ok()) result = client.status();
  return result;
}

}  // namespace holo::pods
