// holoport-bench segment: foreground segmentation and colour calibration
// (issue 3, stages 1–2) on a standard workload.
//
// The background is learned from 30 empty-room frames; then `--frames`
// (default 30) frames are segmented. Figures: `ms` (stage segment, all pods
// of one frame set, median), `mask_iou` (mean over pods and frames) for the
// CRF result (`"mode":"crf"`), the unary term alone (`"mode":"unary"`) and
// OpenCV's MOG2 (`"peer":"mog2"`, colour only, trained on the same frames);
// colour calibration time and `color_error` before/after (mean absolute RGB
// difference, 0..255).
//
// Extra arguments `name=value` override SegmenterOptions fields, e.g.
// `holoport-bench segment crf_weight=4 threads=1`.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/metrics/image_metrics.h"
#include "server/segment/color_calibration.h"
#include "server/segment/mog2_baseline.h"
#include "server/segment/segmenter.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::bench {
namespace {

bool SetOption(SegmenterOptions* o, const std::string& kv) {
  const size_t eq = kv.find('=');
  if (eq == std::string::npos) return false;
  const std::string key = kv.substr(0, eq);
  char* end = nullptr;
  const double v = std::strtod(kv.c_str() + eq + 1, &end);
  if (end == kv.c_str() + eq + 1 || *end != '\0') return false;
  const std::map<std::string, float*> floats = {
      {"depth_sigma_m", &o->depth_sigma_m},
      {"depth_margin_min_m", &o->depth_margin_min_m},
      {"depth_margin_stddevs", &o->depth_margin_stddevs},
      {"depth_appeared_logodds", &o->depth_appeared_logodds},
      {"depth_max_logodds", &o->depth_max_logodds},
      {"depth_edge_m", &o->depth_edge_m},
      {"depth_edge_max_logodds", &o->depth_edge_max_logodds},
      {"depth_noise_at_1m_m", &o->depth_noise_at_1m_m},
      {"chroma_sigma", &o->chroma_sigma},
      {"value_sigma", &o->value_sigma},
      {"dark_level", &o->dark_level},
      {"colour_threshold", &o->colour_threshold},
      {"colour_scale", &o->colour_scale},
      {"colour_max_logodds", &o->colour_max_logodds},
      {"colour_bg_max_logodds", &o->colour_bg_max_logodds},
      {"depth_weight", &o->depth_weight},
      {"colour_weight", &o->colour_weight},
      {"prior_logodds", &o->prior_logodds},
      {"grid_spatial_px", &o->grid_spatial_px},
      {"grid_range", &o->grid_range},
      {"crf_weight", &o->crf_weight},
  };
  const std::map<std::string, int*> ints = {{"crf_iterations", &o->crf_iterations},
                                            {"downsample", &o->downsample},
                                            {"threads", &o->threads}};
  if (auto it = floats.find(key); it != floats.end()) {
    *it->second = static_cast<float>(v);
    return true;
  }
  if (auto it = ints.find(key); it != ints.end()) {
    *it->second = static_cast<int>(v);
    return true;
  }
  return false;
}

// Mean IoU over pods; adds the mean precision and recall to `pr` if given.
double MeanIou(const RgbdFrameSet& fs, const std::vector<ImageGray8>& truth, const std::vector<SegmentDebug>* dbg,
               double* precision = nullptr, double* recall = nullptr) {
  double sum = 0;
  const double n = static_cast<double>(fs.frames.size());
  for (size_t p = 0; p < fs.frames.size(); ++p) {
    auto o = metrics::CompareMasks(dbg ? (*dbg)[p].unary_mask : fs.frames[p].mask, truth[p]);
    HOLO_CHECK_MSG(o.ok(), o.status().ToString());
    sum += o->iou;
    if (precision) *precision += o->precision / n;
    if (recall) *recall += o->recall / n;
  }
  return sum / n;
}

// Mean |a − b| over channels and pixels (0..255) of every pod but `skip`.
double MeanAbsDiff(const RgbdFrameSet& a, const std::vector<ImageRgb8>& b, int skip) {
  double sum = 0;
  size_t n = 0;
  for (size_t p = 0; p < a.frames.size(); ++p) {
    if (static_cast<int>(p) == skip) continue;
    const auto& x = a.frames[p].color.storage();
    const auto& y = b[p].storage();
    for (size_t i = 0; i < x.size(); ++i) sum += std::abs(static_cast<int>(x[i]) - static_cast<int>(y[i]));
    n += x.size();
  }
  return sum / static_cast<double>(std::max<size_t>(1, n));
}

int RunSegmentBench(const BenchArgs& args, const std::vector<std::string>& settings) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("holoport-bench: {}", workload.status().message());
    return 2;
  }
  SegmenterOptions options;
  for (const std::string& e : settings) {
    if (!SetOption(&options, e)) {
      spdlog::error("holoport-bench segment: unknown argument '{}' (expected a SegmenterOptions name=value)", e);
      return 2;
    }
  }
  if (Status st = options.Check(); !st.ok()) {
    spdlog::error("holoport-bench segment: {}", st.ToString());
    return 2;
  }
  const Rig& rig = workload->rig;
  const int num_frames = args.frames > 0 ? args.frames : 30;
  const int background_frames = 30;
  const std::string& wl = args.workload;

  // --- Background learning (untimed) and colour calibration input.
  StudioOptions empty_options = workload->studio;
  empty_options.empty_room = true;
  SyntheticStudio empty(rig, empty_options);
  Segmenter seg(rig, options);
  // The same segmenter on the portable unary path: the peer of the AVX2 one.
  SegmenterOptions portable_options = options;
  portable_options.simd = false;
  Segmenter portable(rig, portable_options);
  Mog2Segmenter mog2(static_cast<int>(rig.pods.size()), Mog2Options{});
  std::vector<RgbdFrameSet> calib_frames;
  RgbdFrameSet fs;
  for (int k = 0; k < background_frames; ++k) {
    empty.RenderFrame(k, &fs, nullptr);
    if (!seg.AddBackgroundFrame(fs).ok() || !portable.AddBackgroundFrame(fs).ok() || !mog2.AddBackgroundFrame(fs).ok())
      return 1;
    if (k < 10) calib_frames.push_back(fs);
  }
  if (!seg.FinishBackground().ok() || !portable.FinishBackground().ok()) return 1;
  if (!args.json) spdlog::info("background learned from {} frames", background_frames);

  // --- Segmentation.
  SyntheticStudio studio(rig, workload->studio);
  StudioGroundTruth gt;
  std::vector<SegmentDebug> dbg;
  std::vector<double> ms, cpu_ms, portable_cpu_ms, mog2_ms;
  double iou = 0, unary_iou = 0, mog2_iou = 0, precision = 0, recall = 0;
  for (int k = 0; k < num_frames; ++k) {
    // Frames spread over the animation (every 7th frame: poses differ).
    studio.RenderFrame(static_cast<int64_t>(k) * 7, &fs, &gt);
    Stopwatch sw;
    const std::clock_t c0 = std::clock();
    if (Status st = seg.Segment(&fs); !st.ok()) {
      spdlog::error("holoport-bench: {}", st.ToString());
      return 1;
    }
    ms.push_back(sw.ElapsedMs());
    cpu_ms.push_back(1000.0 * static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC);
    iou += MeanIou(fs, gt.mask, nullptr, &precision, &recall);
    {
      RgbdFrameSet copy = fs;
      const std::clock_t p0 = std::clock();
      if (!portable.Segment(&copy).ok()) return 1;
      portable_cpu_ms.push_back(1000.0 * static_cast<double>(std::clock() - p0) / CLOCKS_PER_SEC);
    }
    if (!seg.Segment(&fs, &dbg).ok()) return 1;
    unary_iou += MeanIou(fs, gt.mask, &dbg);
    sw.Restart();
    if (!mog2.Segment(&fs).ok()) return 1;
    mog2_ms.push_back(sw.ElapsedMs());
    mog2_iou += MeanIou(fs, gt.mask, nullptr);
  }
  const std::string threads = std::to_string(options.threads);
  const std::string pods = std::to_string(rig.pods.size());
  EmitFigure("segment", wl, "ms", Median(ms), "ms",
             {{"stage", "segment"}, {"mode", "crf"}, {"threads", threads}, {"pods", pods}});
  // CPU time of all threads: barely changed by other load on the machine.
  EmitFigure("segment", wl, "cpu_ms", Median(cpu_ms), "ms",
             {{"stage", "segment"}, {"mode", "crf"}, {"threads", threads}, {"pods", pods}});
  EmitFigure("segment", wl, "cpu_ms", Median(portable_cpu_ms), "ms",
             {{"stage", "segment"}, {"mode", "crf"}, {"threads", threads}, {"pods", pods}, {"unary", "portable"}});
  EmitFigure("segment", wl, "cpu_ratio_vs_portable", Median(cpu_ms) / std::max(1e-9, Median(portable_cpu_ms)), "x",
             {{"stage", "segment"}, {"note", "AVX2 unary (where the CPU has it) over the portable path, same run"}});
  EmitFigure("segment", wl, "mask_iou", iou / num_frames, "1", {{"stage", "segment"}, {"mode", "crf"}});
  EmitFigure("segment", wl, "mask_precision", precision / num_frames, "1", {{"stage", "segment"}, {"mode", "crf"}});
  EmitFigure("segment", wl, "mask_recall", recall / num_frames, "1", {{"stage", "segment"}, {"mode", "crf"}});
  EmitFigure("segment", wl, "mask_iou", unary_iou / num_frames, "1", {{"stage", "segment"}, {"mode", "unary"}});
  EmitFigure("segment", wl, "ms", Median(mog2_ms), "ms",
             {{"stage", "segment"}, {"peer", "mog2"}, {"threads", "1"}, {"pods", pods}});
  EmitFigure("segment", wl, "mask_iou", mog2_iou / num_frames, "1", {{"stage", "segment"}, {"peer", "mog2"}});
  EmitFigure("segment", wl, "mask_iou_ratio_vs_mog2", iou / std::max(1e-9, mog2_iou), "x", {{"stage", "segment"}});

  // --- Colour calibration from the empty-room frames, reference pod 0.
  // color_error between pods: mean |c_a − c_b| over the colour pairs of
  // overlapping background (the estimation input) before/after mapping.
  const int ref = 0;
  ColorCalibrationStats stats;
  Stopwatch sw;
  auto calib = EstimateColorCalibration(rig, calib_frames, ref, ColorCalibrationOptions{}, &stats);
  const double calib_ms = sw.ElapsedMs();
  if (!calib.ok()) {
    spdlog::error("holoport-bench: {}", calib.status().ToString());
    return 1;
  }
  EmitFigure("segment", wl, "ms", calib_ms, "ms", {{"stage", "color_calibration"}, {"frames", "10"}});
  double before = 0, after = 0;
  int total_pairs = 0;
  for (size_t p = 0; p < rig.pods.size(); ++p) {
    before += stats.residual_before[p] * stats.pairs[p];
    after += stats.residual_after[p] * stats.pairs[p];
    total_pairs += stats.pairs[p];
  }
  const std::map<std::string, std::string> overlap = {{"stage", "color_calibration"}, {"against", "other_pods_overlap"},
                                                      {"pairs", std::to_string(total_pairs / 2)}};
  auto with = [](std::map<std::string, std::string> m, const char* mode) {
    m["mode"] = mode;
    return m;
  };
  EmitFigure("segment", wl, "color_error", before / std::max(1, total_pairs), "abs_rgb", with(overlap, "before"));
  EmitFigure("segment", wl, "color_error", after / std::max(1, total_pairs), "abs_rgb", with(overlap, "after"));

  // Against the truth: the same frame without colour variation, mapped into
  // the reference pod's colour space (what a perfect calibration gives). The
  // reference pod's own map truth → observed is fitted per channel from its
  // pixels (exact correspondence).
  StudioOptions true_options = workload->studio;
  true_options.color_variation = false;
  SyntheticStudio truth_studio(rig, true_options);
  RgbdFrameSet observed, truth;
  studio.RenderFrame(60, &observed, nullptr);
  truth_studio.RenderFrame(60, &truth, nullptr);
  Eigen::Vector3f gain, offset;
  for (int c = 0; c < 3; ++c) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    size_t n = 0;
    const auto& t = truth.frames[ref].color.storage();
    const auto& o = observed.frames[ref].color.storage();
    for (size_t i = c; i < t.size(); i += 3) {
      if (o[i] <= 2 || o[i] >= 253) continue;
      sx += t[i], sy += o[i], sxx += static_cast<double>(t[i]) * t[i], sxy += static_cast<double>(t[i]) * o[i];
      ++n;
    }
    gain[c] = static_cast<float>((n * sxy - sx * sy) / (n * sxx - sx * sx));
    offset[c] = static_cast<float>((sy - gain[c] * sx) / n);
  }
  std::vector<ImageRgb8> expected(rig.pods.size());
  for (size_t p = 0; p < rig.pods.size(); ++p) {
    expected[p] = truth.frames[p].color;
    for (size_t i = 0; i < expected[p].storage().size(); ++i) {
      const int c = static_cast<int>(i % 3);
      expected[p].storage()[i] = static_cast<uint8_t>(
          std::clamp(gain[c] * truth.frames[p].color.storage()[i] + offset[c] + 0.5f, 0.0f, 255.0f));
    }
  }
  const std::map<std::string, std::string> vs_truth = {
      {"stage", "color_calibration"}, {"against", "truth_in_reference_colours"}, {"frame", "60"}};
  EmitFigure("segment", wl, "color_error", MeanAbsDiff(observed, expected, ref), "abs_rgb", with(vs_truth, "before"));
  sw.Restart();
  calib->Apply(&observed);
  const double apply_ms = sw.ElapsedMs();
  EmitFigure("segment", wl, "color_error", MeanAbsDiff(observed, expected, ref), "abs_rgb", with(vs_truth, "after"));
  EmitFigure("segment", wl, "ms", apply_ms, "ms", {{"stage", "color_apply"}, {"pods", pods}});
  return 0;
}

}  // namespace

BenchFn SetupSegment(CLI::App& app) {
  DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto settings = std::make_shared<std::vector<std::string>>();
  app.add_option("settings", *settings, "SegmenterOptions fields to change, as NAME=VALUE (e.g. depth_sigma_m=0.02)");
  return [settings](const BenchArgs& args) { return RunSegmentBench(args, *settings); };
}

HOLO_REGISTER_BENCH_OPTIONS("segment", "foreground segmentation (CRF vs unary vs MOG2) and colour calibration",
                            SetupSegment);

}  // namespace holo::bench
