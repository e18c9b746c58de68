// holoport-bench stereo: slanted-plane PatchMatch against OpenCV's StereoSGBM
// (the peer, same run, same threads; server/stereo/sgbm.h, padded so that
// it gives the image's left columns a disparity too) on the studio's active-stereo pairs and
// on the Middlebury 2006 "Aloe" pair; and the fused mesh from stereo depth
// against the fused mesh from the studio's direct depth.
//
// Figures per method (patchmatch | sgbm) and data (studio | middlebury):
// bad1_pct / bad2_pct (pixels with ground truth whose disparity is off by
// more than 1 / 2 px or missing), depth_err_mm (mean |z − z_true| where the
// method gives a disparity), density_pct, ms and cpu_ms per stereo pair
// (median of --repeats), and on the studio ms per frame set (all pods).
// On the studio the same figures over the person's pixels alone
// ("pixels":"person", the truth's foreground mask) for patchmatch, sgbm and
// patchmatch_roi: PatchMatch in the region the site's policy gives
// (server/stereo/stereo_roi.h) in steady state: the policy sees the
// previous frame matched whole, then the measured frame is matched in its
// region with its capped search range (matched_pct: the region's share of
// the image; full_pairs: pairs
// the policy matched whole anyway). ms_per_frame_set_amortized adds the
// policy's periodic full match: (full + (full_every − 1) · region) /
// full_every, from this run's medians. patchmatch_temporal: the same
// region, one matcher per pod started from its own planes of the previous
// frame (PatchMatchOptions::temporal; the previous frame matched untimed
// before each timed run). patchmatch_search: a whole pair as the site's
// policy treats it when one is due (StereoRoiOptions::search_with_sgbm): a
// fresh policy's Match, i.e. SGBM over the whole pair, then PatchMatch
// (afresh) around the foreground it found; its ms and cpu_ms include both,
// and ms_per_frame_set_amortized with "whole":"sgbm_search" is
// (search + (full_every − 1) · temporal) / full_every, the site's default.
// The studio's frames are 10·k + 1 (frame 10·k is the region's previous
// frame).
//
// Options: --middlebury DIR (default ../shared/data/stereo next to the
// repository: a folder holding aloeL.jpg, aloeR.jpg, aloeGT.png, or a parent
// of one), --threads N (2), --baseline M (0.15), --iterations N,
// --coarse-levels N and --fine-iterations N (PatchMatch), --temporal-iterations N,
// --temporal-refine-start N and --temporal-refine-per-sweep N (patchmatch_temporal),
// --light-right-view on|off (PatchMatchOptions::light_right_view, on),
// --final-window-step N (PatchMatchOptions::final_window_step; 0: no dense last pass),
// --edge-shift N (PatchMatchOptions::edge_shift_px; 0: no edge pass),
// --roi-shape spans|box (StereoRoiOptions::row_spans: the regions as row
// spans around the person, the default, or their bounding boxes),
// --fuse-frames N (2; 0 skips the fused-mesh comparison; patchmatch_temporal's
// fused mesh comes after a run of 10 frames; method sgbm: the peer's depth
// of the same pairs fused alike), --contact-sheet PNG.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "bench.h"
#include "common/image_io.h"
#include "common/log.h"
#include "common/metrics/mesh_distance.h"
#include "common/visualize.h"
#include "server/fusion/tsdf.h"
#include "server/stereo/patchmatch.h"
#include "server/stereo/sgbm.h"
#include "server/stereo/stereo_depth.h"
#include "server/stereo/stereo_roi.h"
#include "studio/stereo_render.h"
#include "studio/workloads.h"

namespace holo::bench {
namespace {

struct Scores {
  double bad1 = 0, bad2 = 0, depth_err_mm = 0, density = 0;
  size_t n = 0, bad1_n = 0, bad2_n = 0, valid_n = 0, depth_n = 0;
  double depth_sum = 0;
  void Add(float est, float truth, double fb_mm, double dmin_offset) {
    if (!(truth > 0.0f)) return;
    ++n;
    const bool ok = est > 0.0f;
    const float err = ok ? std::abs(est - truth) : 1e9f;
    bad1_n += err > 1.0f;
    bad2_n += err > 2.0f;
    if (!ok) return;
    ++valid_n;
    depth_sum += std::abs(fb_mm / (est + dmin_offset) - fb_mm / (truth + dmin_offset));
    ++depth_n;
  }
  void Finish() {
    bad1 = 100.0 * bad1_n / std::max<size_t>(1, n);
    bad2 = 100.0 * bad2_n / std::max<size_t>(1, n);
    density = 100.0 * valid_n / std::max<size_t>(1, n);
    depth_err_mm = depth_sum / std::max<size_t>(1, depth_n);
  }
};

struct Timer {
  std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
  double cpu0 = ProcessCpuMs();
  double Ms() const { return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count(); }
  double CpuMs() const { return ProcessCpuMs() - cpu0; }
};

struct MethodRun {
  Scores scores;
  Scores person;  // over the truth's foreground pixels
  std::vector<double> ms, cpu_ms;  // per pair
  std::vector<double> set_ms;      // per frame set (studio)
};

void EmitMethod(const std::string& wl, const std::string& method, const std::string& data, MethodRun& r,
                const std::map<std::string, std::string>& extra, bool all_pixels = true) {
  r.scores.Finish();
  r.person.Finish();
  auto q = extra;
  q["method"] = method;
  q["data"] = data;
  q["content"] = "truth";
  if (r.person.n > 0) {
    auto pq = q;
    pq["pixels"] = "person";
    EmitFigure("stereo", wl, "bad2_pct", r.person.bad2, "%", pq);
    EmitFigure("stereo", wl, "bad1_pct", r.person.bad1, "%", pq);
    EmitFigure("stereo", wl, "depth_err_mm", r.person.depth_err_mm, "mm", pq);
    EmitFigure("stereo", wl, "density_pct", r.person.density, "%", pq);
  }
  if (!all_pixels) {
    EmitFigure("stereo", wl, "ms", Median(r.ms), "ms", q);
    EmitFigure("stereo", wl, "cpu_ms", Median(r.cpu_ms), "ms", q);
    if (!r.set_ms.empty()) EmitFigure("stereo", wl, "ms_per_frame_set", Median(r.set_ms), "ms", q);
    return;
  }
  q["pixels"] = "all";
  EmitFigure("stereo", wl, "bad2_pct", r.scores.bad2, "%", q);
  EmitFigure("stereo", wl, "bad1_pct", r.scores.bad1, "%", q);
  EmitFigure("stereo", wl, "depth_err_mm", r.scores.depth_err_mm, "mm", q);
  EmitFigure("stereo", wl, "density_pct", r.scores.density, "%", q);
  EmitFigure("stereo", wl, "ms", Median(r.ms), "ms", q);
  EmitFigure("stereo", wl, "cpu_ms", Median(r.cpu_ms), "ms", q);
  if (!r.set_ms.empty()) EmitFigure("stereo", wl, "ms_per_frame_set", Median(r.set_ms), "ms", q);
}

ImageRgb8 Gray(const ImageGray8& g) {
  ImageRgb8 o(g.width(), g.height());
  for (size_t i = 0; i < g.num_pixels(); ++i) o.data()[3 * i] = o.data()[3 * i + 1] = o.data()[3 * i + 2] = g.data()[i];
  return o;
}

// Error map: grey = within 1 px, yellow = 1..2 px off, red = more than 2 px off, black = missing.
ImageRgb8 ErrorMap(const ImageFloat& est, const ImageFloat& truth) {
  ImageRgb8 o(est.width(), est.height());
  for (size_t i = 0; i < est.num_pixels(); ++i) {
    uint8_t* p = o.data() + 3 * i;
    const float t = truth.data()[i], e = est.data()[i];
    if (!(t > 0.0f)) { p[0] = p[1] = p[2] = 40; continue; }
    if (!(e > 0.0f)) { p[0] = p[1] = p[2] = 0; continue; }
    const float err = std::abs(e - t);
    if (err <= 1.0f) { p[0] = p[1] = p[2] = 170; } else if (err <= 2.0f) { p[0] = 230; p[1] = 200; p[2] = 0; }
    else { p[0] = 220; p[1] = 30; p[2] = 30; }
  }
  return o;
}

ImageDepth16 DepthOf(const ImageFloat& disp, double fb_mm) {
  ImageDepth16 d(disp.width(), disp.height());
  for (size_t i = 0; i < disp.num_pixels(); ++i) {
    const float v = disp.data()[i];
    d.data()[i] = v > 0.0f ? static_cast<uint16_t>(std::min(65535.0, std::lround(fb_mm / v) * 1.0)) : 0;
  }
  return d;
}

int Fail(const std::string& m) {
  spdlog::error("holoport-bench stereo: {}", m);
  return 2;
}

// The benchmark's own options (holoport-bench stereo --help).
struct StereoBenchOptions {
  std::string middlebury = std::string(HOLO_SOURCE_DIR) + "/../shared/data/stereo";  // Middlebury pairs
  std::string contact_sheet;                                                         // PNG of the depth maps
  int threads = 2;
  int iterations = -1;  // PatchMatch iterations (-1: its default)
  int coarse_levels = -1, fine_iterations = -1;  // PatchMatch coarse to fine (-1: its defaults)
  // patchmatch_temporal's PatchMatchOptions (-1: their defaults)
  int temporal_iterations = -1, temporal_refine_start = -1, temporal_refine_per_sweep = -1;
  double temporal_still = -1;
  int fuse_frames = 2;  // frames fused from stereo vs direct depth (0: skip)
  bool light_right_view = true;  // PatchMatchOptions::light_right_view
  int final_window_step = -1;    // PatchMatchOptions::final_window_step (-1: its default)
  int edge_shift = -1;           // PatchMatchOptions::edge_shift_px (-1: its default)
  bool roi_spans = true;         // StereoRoiOptions::row_spans
  double baseline = kDefaultStereoBaselineM;
};

// patchmatch_temporal's settings from the options (on a temporal matcher's options).
void SetTemporal(const StereoBenchOptions& o, PatchMatchOptions* pm) {
  pm->temporal = true;
  if (o.temporal_iterations > 0) pm->temporal_iterations = o.temporal_iterations;
  if (o.temporal_refine_start >= 0) pm->temporal_refine_start = o.temporal_refine_start;
  if (o.temporal_refine_per_sweep >= 0) pm->temporal_refine_per_sweep = o.temporal_refine_per_sweep;
  if (o.temporal_still >= 0) pm->temporal_still = static_cast<float>(o.temporal_still);
}

int RunStereoBench(const BenchArgs& args, const StereoBenchOptions& o) {
  const std::string& middlebury = o.middlebury;
  const std::string& sheet_path = o.contact_sheet;
  const int threads = o.threads, iterations = o.iterations, fuse_frames = o.fuse_frames;
  const double baseline = o.baseline;
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) return Fail(workload.status().message());
  const std::string& wl = workload->name;
  cv::setNumThreads(threads);

  // ---- Studio pairs -------------------------------------------------------
  const Rig rig = WithStereoPods(workload->rig, baseline);
  if (Status s = rig.Check(); !s.ok()) return Fail(s.ToString());
  StudioOptions so = workload->studio;
  so.threads = threads;
  auto studio = SyntheticStudio::Create(rig, so);
  if (!studio.ok()) return Fail(studio.status().ToString());
  StereoDepthOptions sdo;
  sdo.roi.enabled = false;  // the full run; sdo_roi below
  sdo.patchmatch.threads = threads;
  if (iterations > 0) sdo.patchmatch.iterations = iterations;
  if (o.coarse_levels >= 0) sdo.patchmatch.coarse_levels = o.coarse_levels;
  if (o.fine_iterations > 0) sdo.patchmatch.fine_iterations = o.fine_iterations;
  sdo.patchmatch.light_right_view = o.light_right_view;
  if (o.final_window_step >= 0) sdo.patchmatch.final_window_step = o.final_window_step;
  if (o.edge_shift >= 0) sdo.patchmatch.edge_shift_px = o.edge_shift;
  auto source = StereoStudioSource::Create(studio->get(), sdo);
  if (!source.ok()) return Fail(source.status().ToString());
  StereoDepthOptions sdo_roi = sdo;
  sdo_roi.roi.enabled = true;
  sdo_roi.roi.fps = (*studio)->options().fps;
  sdo_roi.roi.row_spans = o.roi_spans;
  auto renderer = StereoStudioRenderer::Create(studio->get(), rig, sdo.render);
  if (!renderer.ok()) return Fail(renderer.status().ToString());
  PatchMatchOptions pmo = sdo.patchmatch;
  StereoSearchRange(rig.pods[0], sdo.near_m, sdo.far_m, &pmo);
  for (const auto& pod : rig.pods) {
    PatchMatchOptions r = pmo;
    StereoSearchRange(pod, sdo.near_m, sdo.far_m, &r);
    pmo.min_disparity = std::min(pmo.min_disparity, r.min_disparity);
    pmo.max_disparity = std::max(pmo.max_disparity, r.max_disparity);
  }
  PatchMatchStereo pm(pmo);
  SgbmStereo sgbm(pmo.min_disparity, pmo.max_disparity);
  const int frames = args.frames > 0 ? args.frames : 3;
  const std::map<std::string, std::string> studio_q = {
      {"pods", std::to_string(rig.pods.size())},
      {"resolution", std::to_string(rig.pods[0].stereo.ir.width) + "x" + std::to_string(rig.pods[0].stereo.ir.height)},
      {"threads", std::to_string(threads)},
      {"frames", std::to_string(frames)},
      {"avx2", pm.uses_avx2() ? "1" : "0"}};
  if (!args.json)
    spdlog::info("studio: {}, {} stereo pods, baseline {:.3f} m, disparity [{:g}, {:g}], {} frames", wl,
                 rig.pods.size(), baseline, pmo.min_disparity, pmo.max_disparity, frames);
  MethodRun pm_run, sgbm_run, roi_run, tmp_run, search_run;
  // patchmatch_temporal: one matcher per pod (PatchMatchOptions::temporal),
  // in the same region as patchmatch_roi, started from its planes of the
  // previous frame (matched untimed before every timed run).
  PatchMatchOptions pmo_t = pmo;
  SetTemporal(o, &pmo_t);
  std::vector<std::unique_ptr<PatchMatchStereo>> pm_t;
  for (size_t p = 0; p < rig.pods.size(); ++p) pm_t.push_back(std::make_unique<PatchMatchStereo>(pmo_t));
  ImageFloat d_tmp;
  std::vector<StereoPair> pairs, previous;
  ImageFloat d_pm, d_sgbm, d_roi;
  std::vector<ImageRgb8> sheet;
  int64_t roi_area = 0, image_area = 0, search_area = 0;
  int roi_full_pairs = 0;
  ImageFloat d_search;
  for (int f = 0; f < frames; ++f) {
    const int64_t frame = static_cast<int64_t>(f) * 10 + 1;
    (*renderer)->Render(frame - 1, &previous);
    (*renderer)->Render(frame, &pairs);
    double set_pm = 0, set_sgbm = 0, set_roi = 0, set_tmp = 0, set_search = 0;
    for (size_t p = 0; p < pairs.size(); ++p) {
      const StereoPair& sp = pairs[p];
      const double fb_mm = sp.fx * sp.baseline_m * 1000.0;
      // The region policy in steady state: the previous frame matched whole.
      StereoRoiPolicy policy(rig.pods[p], sdo_roi.roi);
      const ImageRect prev_region = policy.Next(frame - 1);
      if (Status s = pm.Compute(previous[p].left, previous[p].right, prev_region, &d_roi); !s.ok())
        return Fail(s.ToString());
      policy.Update(frame - 1, prev_region, d_roi);
      policy.Next(frame);
      const RowSpans region = policy.spans();
      roi_area += region.area();
      image_area += static_cast<int64_t>(sp.left.width()) * sp.left.height();
      roi_full_pairs += region.IsFull(sp.left.width());
      for (int r = 0; r < std::max(1, args.repeats); ++r) {
        Timer v;
        if (Status s = pm.Compute(sp.left, sp.right, region, policy.max_disparity(), &d_roi); !s.ok())
          return Fail(s.ToString());
        roi_run.ms.push_back(v.Ms());
        roi_run.cpu_ms.push_back(v.CpuMs());
        if (r == 0) set_roi += roi_run.ms.back();
        if (Status s = pm_t[p]->Compute(previous[p].left, previous[p].right, prev_region, &d_tmp); !s.ok())
          return Fail(s.ToString());
        Timer w;
        if (Status s = pm_t[p]->Compute(sp.left, sp.right, region, policy.max_disparity(), &d_tmp); !s.ok())
          return Fail(s.ToString());
        tmp_run.ms.push_back(w.Ms());
        tmp_run.cpu_ms.push_back(w.CpuMs());
        if (r == 0) set_tmp += tmp_run.ms.back();
        {  // patchmatch_search: a whole pair due, searched with SGBM, PatchMatch around the person found
          StereoRoiPolicy fresh(rig.pods[p], sdo_roi.roi);
          Timer x;
          auto searched = fresh.Match(&pm, frame, sp.left, sp.right, &d_search);
          if (!searched.ok()) return Fail(searched.status().ToString());
          search_run.ms.push_back(x.Ms());
          search_run.cpu_ms.push_back(x.CpuMs());
          if (r == 0) {
            set_search += search_run.ms.back();
            search_area += searched->area();
          }
        }
        Timer t;
        if (Status s = pm.Compute(sp.left, sp.right, &d_pm); !s.ok()) return Fail(s.ToString());
        pm_run.ms.push_back(t.Ms());
        pm_run.cpu_ms.push_back(t.CpuMs());
        if (r == 0) set_pm += pm_run.ms.back();
        Timer u;
        sgbm.Compute(sp.left, sp.right, &d_sgbm);
        sgbm_run.ms.push_back(u.Ms());
        sgbm_run.cpu_ms.push_back(u.CpuMs());
        if (r == 0) set_sgbm += sgbm_run.ms.back();
      }
      for (size_t i = 0; i < sp.disparity.num_pixels(); ++i) {
        pm_run.scores.Add(d_pm.data()[i], sp.disparity.data()[i], fb_mm, 0.0);
        sgbm_run.scores.Add(d_sgbm.data()[i], sp.disparity.data()[i], fb_mm, 0.0);
        if (sp.mask.data()[i] == 0) continue;
        pm_run.person.Add(d_pm.data()[i], sp.disparity.data()[i], fb_mm, 0.0);
        sgbm_run.person.Add(d_sgbm.data()[i], sp.disparity.data()[i], fb_mm, 0.0);
        roi_run.person.Add(d_roi.data()[i], sp.disparity.data()[i], fb_mm, 0.0);
        tmp_run.person.Add(d_tmp.data()[i], sp.disparity.data()[i], fb_mm, 0.0);
        search_run.person.Add(d_search.data()[i], sp.disparity.data()[i], fb_mm, 0.0);
      }
      if (!sheet_path.empty() && f == 0 && p < 4) {
        const uint16_t near_mm = 1000, far_mm = 6000;
        sheet.push_back(Gray(sp.left));
        sheet.push_back(ColorizeDepth(DepthOf(sp.disparity, fb_mm), near_mm, far_mm));
        sheet.push_back(ColorizeDepth(DepthOf(d_pm, fb_mm), near_mm, far_mm));
        sheet.push_back(ErrorMap(d_pm, sp.disparity));
        sheet.push_back(ColorizeDepth(DepthOf(d_sgbm, fb_mm), near_mm, far_mm));
        sheet.push_back(ErrorMap(d_sgbm, sp.disparity));
      }
    }
    pm_run.set_ms.push_back(set_pm);
    sgbm_run.set_ms.push_back(set_sgbm);
    roi_run.set_ms.push_back(set_roi);
    tmp_run.set_ms.push_back(set_tmp);
    search_run.set_ms.push_back(set_search);
  }
  EmitMethod(wl, "patchmatch", "studio", pm_run, studio_q);
  EmitMethod(wl, "sgbm", "studio", sgbm_run, studio_q);
  {
    // A region method's figures; returns its qualifiers for the figures
    // that follow it.
    auto emit_region_method = [&](const std::string& method, MethodRun& run) {
      auto q = studio_q;
      q["full_every"] = std::to_string(sdo_roi.roi.full_every);
      q["roi_shape"] = sdo_roi.roi.row_spans ? "spans" : "box";
      EmitMethod(wl, method, "studio", run, q, /*all_pixels=*/false);
      q["method"] = method;
      q["data"] = "studio";
      q["content"] = "truth";
      return q;
    };
    const double roi_set = Median(roi_run.set_ms), full_set = Median(pm_run.set_ms);
    const double tmp_set = Median(tmp_run.set_ms);
    const int n = sdo_roi.roi.full_every;
    const auto image_pct = [&](int64_t area) {
      return 100.0 * static_cast<double>(area) / static_cast<double>(std::max<int64_t>(1, image_area));
    };
    auto q = emit_region_method("patchmatch_roi", roi_run);
    EmitFigure("stereo", wl, "matched_pct", image_pct(roi_area), "%", q);
    EmitFigure("stereo", wl, "full_pairs", roi_full_pairs, "1", q);
    EmitFigure("stereo", wl, "ms_per_frame_set_amortized", (full_set + (n - 1) * roi_set) / n, "ms", q);
    q = emit_region_method("patchmatch_temporal", tmp_run);
    EmitFigure("stereo", wl, "ms_per_frame_set_amortized", (full_set + (n - 1) * tmp_set) / n, "ms", q);
    // The site's default: whole pairs due are searched (patchmatch_search),
    // the frames between are patchmatch_temporal.
    q["whole"] = "sgbm_search";
    EmitFigure("stereo", wl, "ms_per_frame_set_amortized", (Median(search_run.set_ms) + (n - 1) * tmp_set) / n,
               "ms", q);
    q = emit_region_method("patchmatch_search", search_run);
    EmitFigure("stereo", wl, "matched_pct", image_pct(search_area), "%", q);
  }
  if (!sheet_path.empty()) {
    std::vector<const ImageRgb8*> tiles;
    for (const auto& t : sheet) tiles.push_back(&t);
    const ImageRgb8 img = TileImages(tiles, 6, 2);
    if (Status s = WriteImageRgb8(sheet_path, img); !s.ok()) return Fail(s.ToString());
    if (!args.json) spdlog::info("contact sheet: {}", sheet_path);
  }

  // ---- Middlebury ---------------------------------------------------------
  std::string dir = middlebury;
  if (!std::filesystem::exists(dir + "/aloeL.jpg") &&
      std::filesystem::exists(dir + "/middlebury2006_aloe_full/aloeL.jpg"))
    dir += "/middlebury2006_aloe_full";
  if (!std::filesystem::exists(dir + "/aloeL.jpg") || !std::filesystem::exists(dir + "/aloeR.jpg") ||
      !std::filesystem::exists(dir + "/aloeGT.png")) {
    spdlog::info(
        "holoport-bench stereo: Middlebury pair not found under {} (need aloeL.jpg, aloeR.jpg, aloeGT.png; "
        "pass --middlebury DIR): middlebury figures SKIPPED",
        middlebury);
    EmitFigure("stereo", wl, "middlebury_available", 0, "1", {{"data", "middlebury"}, {"path", middlebury}});
  } else {
    const cv::Mat l = cv::imread(dir + "/aloeL.jpg", cv::IMREAD_GRAYSCALE);
    const cv::Mat r = cv::imread(dir + "/aloeR.jpg", cv::IMREAD_GRAYSCALE);
    const cv::Mat gt = cv::imread(dir + "/aloeGT.png", cv::IMREAD_GRAYSCALE);
    if (l.empty() || r.empty() || gt.empty() || l.size() != r.size() || l.size() != gt.size())
      return Fail("Middlebury images under " + dir + " unreadable or of different sizes");
    ImageGray8 li(l.cols, l.rows), ri(l.cols, l.rows);
    ImageFloat truth(l.cols, l.rows);
    for (int y = 0; y < l.rows; ++y)
      for (int x = 0; x < l.cols; ++x) {
        li.at(x, y) = l.at<uint8_t>(y, x);
        ri.at(x, y) = r.at<uint8_t>(y, x);
        truth.at(x, y) = gt.at<uint8_t>(y, x);
      }
    PatchMatchOptions mo = sdo.patchmatch;
    mo.min_disparity = 0;
    mo.max_disparity = 256;
    PatchMatchStereo pm_m(mo);
    SgbmStereo sgbm_m(0, 256);
    MethodRun a, b;
    // Published geometry of the 2006 full-size sets: f = 3740 px, B = 160 mm;
    // the disparity offset (dmin) of Aloe is not in the shipped data, taken as 0.
    const double fb_mm = 3740.0 * 160.0;
    for (int rep = 0; rep < std::max(1, std::min(args.repeats, 3)); ++rep) {
      Timer t;
      if (Status s = pm_m.Compute(li, ri, &d_pm); !s.ok()) return Fail(s.ToString());
      a.ms.push_back(t.Ms());
      a.cpu_ms.push_back(t.CpuMs());
      Timer u;
      sgbm_m.Compute(li, ri, &d_sgbm);
      b.ms.push_back(u.Ms());
      b.cpu_ms.push_back(u.CpuMs());
    }
    for (size_t i = 0; i < truth.num_pixels(); ++i) {
      a.scores.Add(d_pm.data()[i], truth.data()[i], fb_mm, 0.0);
      b.scores.Add(d_sgbm.data()[i], truth.data()[i], fb_mm, 0.0);
    }
    const std::map<std::string, std::string> mq = {
        {"pair", "aloe_full"}, {"resolution", std::to_string(l.cols) + "x" + std::to_string(l.rows)},
        {"threads", std::to_string(threads)}, {"depth_model", "f3740px_B160mm_dmin0_assumed"}};
    EmitMethod(wl, "patchmatch", "middlebury", a, mq);
    EmitMethod(wl, "sgbm", "middlebury", b, mq);
  }

  // ---- Fused mesh: stereo depth vs the studio's direct depth ---------------
  if (fuse_frames > 0) {
    TsdfOptions to;
    to.voxel_size = workload->voxel_size_m;
    to.threads = threads;
    auto vol = TsdfVolume::Create(to);
    if (!vol.ok()) return Fail(vol.status().ToString());
    std::vector<double> chamfer_vs_direct, chamfer_stereo_truth, chamfer_direct_truth;
    std::vector<double> chamfer_roi_vs_direct, chamfer_roi_truth, chamfer_tmp_vs_direct, chamfer_tmp_truth;
    RgbdFrameSet direct, stereo, stereo_roi, stereo_tmp, stereo_sgbm;
    std::vector<double> chamfer_sgbm_vs_direct, chamfer_sgbm_truth;
    std::vector<StereoPair> fuse_pairs;
    ImageFloat d_fuse_sgbm;
    // patchmatch_temporal: regions started from the last planes, over a run
    // of kChain consecutive frames ending at the fused one (the errors of a
    // chain of temporal starts, with the policy's whole pairs in between).
    constexpr int kChain = 10;
    StereoDepthOptions sdo_tmp = sdo_roi;
    SetTemporal(o, &sdo_tmp.patchmatch);
    StudioGroundTruth gt;
    for (int f = 0; f < fuse_frames; ++f) {
      const int64_t frame = static_cast<int64_t>(f) * 10 + 5;
      (*studio)->RenderFrame(frame, &direct, &gt);
      if (Status s = (*source)->RenderFrame(frame, &stereo, &fuse_pairs); !s.ok()) return Fail(s.ToString());
      // The peer: SGBM's depth of the same pairs.
      stereo_sgbm = stereo;
      for (size_t p = 0; p < fuse_pairs.size(); ++p) {
        sgbm.Compute(fuse_pairs[p].left, fuse_pairs[p].right, &d_fuse_sgbm);
        if (Status s = DisparityToDepth((*source)->rig().pods[p], d_fuse_sgbm, sdo.far_m, &stereo_sgbm.frames[p].depth);
            !s.ok())
          return Fail(s.ToString());
      }
      // The region policy in steady state: a fresh source matches frame − 1 whole, then `frame` in the regions.
      auto roi_source = StereoStudioSource::Create(studio->get(), sdo_roi);
      if (!roi_source.ok()) return Fail(roi_source.status().ToString());
      if (Status s = (*roi_source)->RenderFrame(frame - 1, &stereo_roi, nullptr); !s.ok()) return Fail(s.ToString());
      if (Status s = (*roi_source)->RenderFrame(frame, &stereo_roi, nullptr); !s.ok()) return Fail(s.ToString());
      auto tmp_source = StereoStudioSource::Create(studio->get(), sdo_tmp);
      if (!tmp_source.ok()) return Fail(tmp_source.status().ToString());
      for (int64_t k = frame - kChain + 1; k <= frame; ++k)
        if (Status s = (*tmp_source)->RenderFrame(k, &stereo_tmp, nullptr); !s.ok()) return Fail(s.ToString());
      for (size_t p = 0; p < direct.frames.size(); ++p) {
        direct.frames[p].mask = gt.mask[p];
        stereo.frames[p].mask = gt.mask[p];
        stereo_roi.frames[p].mask = gt.mask[p];
        stereo_tmp.frames[p].mask = gt.mask[p];
        stereo_sgbm.frames[p].mask = gt.mask[p];
      }
      // Each frame set fused alone.
      auto fuse = [&](const RgbdFrameSet& set, Mesh* mesh) {
        (*vol)->Reset();
        HOLO_RETURN_IF_ERROR((*vol)->Integrate(rig, set));
        (*vol)->ExtractMesh(mesh);
        return OkStatus();
      };
      Mesh m_direct, m_stereo, m_roi, m_tmp, m_sgbm;
      for (auto [set, mesh] : {std::pair{&direct, &m_direct}, std::pair{&stereo, &m_stereo},
                               std::pair{&stereo_roi, &m_roi}, std::pair{&stereo_tmp, &m_tmp},
                               std::pair{&stereo_sgbm, &m_sgbm}})
        if (Status s = fuse(*set, mesh); !s.ok()) return Fail(s.ToString());
      metrics::MeshDistanceOptions mo;
      mo.num_threads = threads;
      auto vs = metrics::ComputeMeshDistance(m_stereo, m_direct, mo);
      auto st = metrics::ComputeMeshDistance(m_stereo, gt.foreground_mesh, mo);
      auto dt = metrics::ComputeMeshDistance(m_direct, gt.foreground_mesh, mo);
      auto rv = metrics::ComputeMeshDistance(m_roi, m_direct, mo);
      auto rt = metrics::ComputeMeshDistance(m_roi, gt.foreground_mesh, mo);
      auto tv = metrics::ComputeMeshDistance(m_tmp, m_direct, mo);
      auto tt = metrics::ComputeMeshDistance(m_tmp, gt.foreground_mesh, mo);
      auto gv = metrics::ComputeMeshDistance(m_sgbm, m_direct, mo);
      auto gt_ = metrics::ComputeMeshDistance(m_sgbm, gt.foreground_mesh, mo);
      if (!vs.ok() || !st.ok() || !dt.ok() || !rv.ok() || !rt.ok() || !tv.ok() || !tt.ok() || !gv.ok() || !gt_.ok())
        return Fail("mesh distance failed (empty fused mesh?)");
      chamfer_sgbm_vs_direct.push_back(gv->chamfer_mm);
      chamfer_sgbm_truth.push_back(gt_->chamfer_mm);
      chamfer_tmp_vs_direct.push_back(tv->chamfer_mm);
      chamfer_tmp_truth.push_back(tt->chamfer_mm);
      chamfer_roi_vs_direct.push_back(rv->chamfer_mm);
      chamfer_roi_truth.push_back(rt->chamfer_mm);
      chamfer_vs_direct.push_back(vs->chamfer_mm);
      chamfer_stereo_truth.push_back(st->chamfer_mm);
      chamfer_direct_truth.push_back(dt->chamfer_mm);
    }
    const std::string n = std::to_string(fuse_frames);
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_vs_direct), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_direct"}, {"frames", n}, {"masks", "truth"},
                {"method", "patchmatch"}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_stereo_truth), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_truth"}, {"frames", n}, {"masks", "truth"},
                {"method", "patchmatch"}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_roi_vs_direct), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_direct"}, {"frames", n}, {"masks", "truth"},
                {"method", "patchmatch_roi"}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_roi_truth), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_truth"}, {"frames", n}, {"masks", "truth"},
                {"method", "patchmatch_roi"}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_tmp_vs_direct), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_direct"}, {"frames", n}, {"masks", "truth"},
                {"method", "patchmatch_temporal"}, {"chain", std::to_string(kChain)}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_tmp_truth), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_truth"}, {"frames", n}, {"masks", "truth"},
                {"method", "patchmatch_temporal"}, {"chain", std::to_string(kChain)}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_sgbm_vs_direct), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_direct"}, {"frames", n}, {"masks", "truth"},
                {"method", "sgbm"}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_sgbm_truth), "mm",
               {{"content", "fused"}, {"compare", "stereo_vs_truth"}, {"frames", n}, {"masks", "truth"},
                {"method", "sgbm"}});
    EmitFigure("stereo", wl, "chamfer_mm", Mean(chamfer_direct_truth), "mm",
               {{"content", "fused"}, {"compare", "direct_vs_truth"}, {"frames", n}, {"masks", "truth"}});
  }
  return 0;
}

BenchFn SetupStereo(CLI::App& app) {
  auto o = std::make_shared<StereoBenchOptions>();
  app.add_option("--middlebury", o->middlebury, "directory of Middlebury stereo pairs")->capture_default_str();
  app.add_option("--contact-sheet", o->contact_sheet, "write a PNG of the depth maps");
  app.add_option("--threads", o->threads, "threads of PatchMatch, SGBM and the studio")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_option("--iterations", o->iterations, "PatchMatch iterations (-1: its default)")->capture_default_str();
  app.add_option("--coarse-levels", o->coarse_levels, "PatchMatch half-resolution levels first (-1: its default)")
      ->capture_default_str();
  app.add_option("--fine-iterations", o->fine_iterations,
                 "PatchMatch iterations at full resolution after the coarse levels (-1: its default)")
      ->capture_default_str();
  app.add_option("--temporal-iterations", o->temporal_iterations,
                 "patchmatch_temporal: iterations from the last planes (-1: its default)")
      ->capture_default_str();
  app.add_option("--temporal-refine-start", o->temporal_refine_start,
                 "patchmatch_temporal: the refinement's range starts at 2^-N (-1: its default)")
      ->capture_default_str();
  app.add_option("--temporal-still", o->temporal_still,
                 "patchmatch_temporal: pixels whose window changed since the last frame by at most this times the "
                 "noise level are left alone (0: none; -1: its default)")
      ->check(CLI::Range(-1.0, 100.0))
      ->capture_default_str();
  app.add_option("--temporal-refine-per-sweep", o->temporal_refine_per_sweep,
                 "patchmatch_temporal: refinement candidates per sweep (-1: its default)")
      ->capture_default_str();
  app.add_option("--light-right-view", o->light_right_view,
                 "PatchMatch: the right view without refinement or vertical sweeps where planes start from the "
                 "coarse level or the last frame (on|off)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, bool>{{"on", true}, {"off", false}}))
      ->capture_default_str();
  app.add_option("--final-window-step", o->final_window_step,
                 "PatchMatch: the dense last pass's window step (0: none; -1: its default)")
      ->check(CLI::Range(-1, 4))
      ->capture_default_str();
  app.add_option("--roi-shape", o->roi_spans,
                 "patchmatch_roi and patchmatch_temporal: the region as row spans around the person or its "
                 "bounding box (spans|box)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, bool>{{"spans", true}, {"box", false}}))
      ->capture_default_str();
  app.add_option("--edge-shift", o->edge_shift,
                 "PatchMatch: the edge pass's window shift, px (0: no edge pass; -1: its default)")
      ->check(CLI::Range(-1, 8))
      ->capture_default_str();
  app.add_option("--fuse-frames", o->fuse_frames, "frames fused from stereo and from direct depth (0: skip)")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  app.add_option("--baseline", o->baseline, "stereo baseline, m")->capture_default_str();
  return [o](const BenchArgs& args) { return RunStereoBench(args, *o); };
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS("stereo",
                            "active stereo: PatchMatch vs OpenCV SGBM (studio, Middlebury), fused mesh vs direct depth",
                            SetupStereo);

}  // namespace holo::bench
