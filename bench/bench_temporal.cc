// holoport-bench temporal: per-frame TSDF fusion vs temporal fusion
// (non-rigid ED tracking + fusion into the warped reference volume,
// server/temporal/) on a workload, judged against the studio's ground truth.
//
//   holoport-bench temporal --workload S8-QVGA|S8-VGA [--frames 30] [--json]
//   options: --solver gn|ceres, --spacing-cm S (node spacing), --max-weight W,
//            --track-points N, --points-per-node P, --reg-weight W, --rot-weight W, --hull-weight W,
//            --iterations N (non-rigid GN steps), --fail-residual-mm R, --no-predict, --still (repeat frame 0), --pcg N (PCG iteration cap), --snap-mm S (still-node snap, 0 = off), --eval-every N (Chamfer every N-th frame),
//            --sparse 0|1 (colour-feature term; default by resolution: on at VGA), --sparse-weight W, --parallel-pcg 0|1,
//            --drop-pod K (pod whose data is removed; -1 = no dropped-pod run),
//            --drop-from F (first frame without it)
//
// HOLO_TEMPORAL_VERBOSE=1: per-frame tracking details on stderr.
// HOLO_TEMPORAL_DIAG=1: per evaluated frame a histogram of the output's
// vertex distances to the truth and Chamfer; at the end the flicker of each
// connected component of the truth mesh (figures' parts, props), both modes.
//
// Masks: the studio's ground-truth masks (MaskSource truth), so segmentation
// cost and errors do not enter the figures. Times: wall clock per frame
// (medians) and cpu_ms (CPU time of all threads per frame, medians).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "common/log.h"
#include "common/metrics/flicker.h"
#include "common/metrics/mesh_distance.h"
#include "common/metrics/surface_sampling.h"
#include "common/metrics/triangle_index.h"
#include "server/temporal/temporal_fusion.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo::bench {
namespace {

struct Extra {
  std::string solver = "gn";
  double spacing_cm = 0;
  double max_weight = 0;
  int track_points = 0;
  double points_per_node = -1;
  double reg_weight = -1, rot_weight = -1, hull_weight = -1;
  int iterations = -1;
  int rigid_iterations = -1;
  int normal_radius = -1;
  double min_track_weight = -1;
  double fail_residual_mm = -1;
  int pcg = -1;
  int data_window = -2;
  double snap_mm = -1;
  int eval_every = 5;
  int drop_pod = 1;
  int drop_from = 10;
  bool predict = true;
  int parallel_pcg = -1;
  int sparse = -1;
  double sparse_weight = -1;
  bool still = false;  // repeat frame 0 (a static scene): checks the warp's resampling
};

// The temporal benchmark's options (holoport-bench temporal --help); a
// negative value keeps the tracker's default.
void DeclareOptions(CLI::App& app, Extra* a) {
  app.add_option("--solver", a->solver, "non-rigid solver: gn or ceres")->capture_default_str();
  app.add_option("--spacing-cm", a->spacing_cm, "deformation node spacing, cm");
  app.add_option("--max-weight", a->max_weight, "TSDF weight cap");
  app.add_option("--track-points", a->track_points, "tracked points");
  app.add_option("--points-per-node", a->points_per_node, "tracked points per node");
  app.add_option("--reg-weight", a->reg_weight, "regularisation weight");
  app.add_option("--rot-weight", a->rot_weight, "rotation weight");
  app.add_option("--hull-weight", a->hull_weight, "visual hull weight");
  app.add_option("--iterations", a->iterations, "Gauss-Newton iterations");
  app.add_option("--rigid-iterations", a->rigid_iterations, "rigid pre-alignment iterations");
  app.add_option("--normal-radius", a->normal_radius, "tracked normals from the TSDF, voxels (0 = mesh)");
  app.add_option("--min-track-weight", a->min_track_weight, "minimum TSDF weight of a tracked point");
  app.add_option("--fail-residual-mm", a->fail_residual_mm, "residual above which tracking resets, mm");
  app.add_flag("--no-predict{false}", a->predict, "no motion prediction");
  app.add_option("--parallel-pcg", a->parallel_pcg, "parallel PCG (0|1)");
  app.add_option("--sparse", a->sparse, "sparse feature term (0|1)");
  app.add_option("--sparse-weight", a->sparse_weight, "sparse feature weight");
  app.add_flag("--still", a->still, "repeat frame 0 (a static scene): checks the warp's resampling");
  app.add_option("--pcg", a->pcg, "PCG iterations");
  app.add_option("--snap-mm", a->snap_mm, "snap distance, mm");
  app.add_option("--eval-every", a->eval_every, "evaluate every N frames")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--data-window", a->data_window, "data term window");
  app.add_option("--drop-pod", a->drop_pod, "pod dropped (-1 = none)")->capture_default_str();
  app.add_option("--drop-from", a->drop_from, "frame from which the pod is dropped")->capture_default_str()->check(CLI::PositiveNumber);
}

// One fusion run (a mode) over the frames, with its figures.
struct TemporalRun {
  std::string mode;
  std::unique_ptr<TemporalFusion> fusion;
  metrics::FlickerAccumulator flicker;
  std::vector<double> track_ms, warp_ms, fuse_ms, mesh_ms, total_ms, cpu_ms;
  std::vector<double> chamfer, completeness, accuracy, exclusive;
  int resets = 0, region_resets = 0, full_resets = 0, lost = 0;
  double failed_nodes = 0, nodes = 0;
  int tracked = 0;
  Mesh mesh;
};

// Whether pod `k` sees point `p` (noise-free depth within 15 mm); with a
// non-zero `normal`, only if the surface faces the pod.
bool PodSees(const Rig& rig, const StudioGroundTruth& gt, size_t k, const Eigen::Vector3f& p,
             const Eigen::Vector3f& normal) {
  const CameraModel cam = rig.pods[k].DepthCamera();
  if (!normal.isZero() && normal.dot(cam.Center() - p) <= 0) return false;
  const Eigen::Vector3f pc = cam.world_from_camera.inverse() * p;
  Eigen::Vector2f px;
  if (!cam.ProjectCamera(pc, &px)) return false;
  const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
  if (u < 0 || v < 0 || u >= gt.depth[k].width() || v >= gt.depth[k].height()) return false;
  const float z = gt.depth[k].at(u, v) * 0.001f;
  return z > 0 && std::abs(z - pc.z()) <= 0.015f;
}

// Truth vertices that pod `pod` alone sees (noise-free depth within 15 mm,
// front-facing), per the ground-truth depth of every pod.
std::vector<Eigen::Vector3f> ExclusiveVertices(const Rig& rig, const StudioGroundTruth& gt, int pod) {
  std::vector<Eigen::Vector3f> out;
  const Mesh& m = gt.foreground_mesh;
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const Eigen::Vector3f& p = m.positions[i];
    int seen_by = 0;
    bool seen_by_pod = false;
    const Eigen::Vector3f n = m.normals.empty() ? Eigen::Vector3f::Zero() : m.normals[i];
    for (size_t k = 0; k < rig.pods.size(); ++k) {
      if (!PodSees(rig, gt, k, p, n)) continue;
      ++seen_by;
      if (static_cast<int>(k) == pod) seen_by_pod = true;
    }
    if (seen_by_pod && seen_by == 1) out.push_back(p);
  }
  return out;
}

double FractionWithin(const Mesh& recon, const std::vector<Eigen::Vector3f>& pts, float threshold) {
  if (pts.empty()) return NAN;
  auto index = metrics::TriangleIndex::Build(recon);
  if (!index.ok() || index->empty()) return 0.0;
  const std::vector<float> d = index->DistanceBatch(pts, threshold * 2, 2);
  size_t hit = 0;
  for (float x : d) hit += x <= threshold;
  return static_cast<double>(hit) / static_cast<double>(pts.size());
}

// HOLO_TEMPORAL_DIAG=1: flicker per connected component of the truth mesh
// (figures' parts, props), per mode, on stderr; for the temporal mode also,
// per component, the graph nodes near it and how many of them failed (and
// why), and the frames where it flickered most.
struct Diag {
  std::vector<metrics::SurfaceSample> samples;
  std::vector<int> comp;  // per sample
  std::vector<size_t> comp_size;
  std::vector<Eigen::Vector3f> comp_centroid;  // frame 0
  int num_comp = 0;
  std::vector<std::vector<float>> prev;                 // per mode
  std::vector<Eigen::Vector3f> prev_pos;                // sample positions, last frame
  std::vector<std::vector<double>> sum, cnt, valid, abs_d;  // per mode, per component
  // Per mode, per component: the flicker sum / count over sample pairs that
  // no pod sees (truth depth) in either frame of the pair.
  std::vector<std::vector<double>> hid_sum, hid_cnt;
  std::vector<uint8_t> visible, prev_visible;  // per sample, this / last frame
  // Truth vertex positions of the last frame, for the tracking error: per
  // node, its displacement against the true motion of the nearest truth
  // vertex (along that vertex's normal and in all).
  std::vector<Eigen::Vector3f> prev_truth, cur_truth;
  std::vector<std::string> track_err;
  std::vector<int> vertex_comp;
  std::vector<double> comp_err_sum, comp_err_cnt;  // along-normal node error per component (frames >= 10)
  std::vector<double> speed_sum;                        // per component, mm per frame
  std::vector<double> frames_seen;
  // Temporal mode, per component: nodes within 3 cm of its samples (warped),
  // failed ones by reason, summed over frames.
  std::vector<double> near_nodes, near_failed, near_res, near_viol, near_stretch, near_affine, near_low_support;
  // Per component, per frame: flicker of each mode (NaN if none).
  std::vector<std::vector<std::array<double, 2>>> timeline;
  std::vector<std::string> frame_notes;
  void Init(const Mesh& truth) {
    std::vector<int> parent(truth.positions.size());
    for (size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
    auto find = [&](int x) {
      while (parent[static_cast<size_t>(x)] != x) x = parent[static_cast<size_t>(x)] = parent[static_cast<size_t>(parent[static_cast<size_t>(x)])];
      return x;
    };
    for (const auto& t : truth.triangles) {
      const int a = find(static_cast<int>(t[0])), b = find(static_cast<int>(t[1])), c = find(static_cast<int>(t[2]));
      parent[static_cast<size_t>(b)] = a;
      parent[static_cast<size_t>(find(c))] = find(a);
    }
    metrics::SamplingOptions so;
    so.num_samples = 20000;
    samples = *metrics::SampleSurface(truth, so);
    std::map<int, int> ids;
    for (const auto& sm : samples) {
      const int r = find(static_cast<int>(truth.triangles[sm.triangle][0]));
      auto it = ids.find(r);
      if (it == ids.end()) it = ids.emplace(r, static_cast<int>(ids.size())).first;
      comp.push_back(it->second);
    }
    num_comp = static_cast<int>(ids.size());
    vertex_comp.assign(truth.positions.size(), -1);
    for (size_t v = 0; v < truth.positions.size(); ++v) {
      auto it = ids.find(find(static_cast<int>(v)));
      if (it != ids.end()) vertex_comp[v] = it->second;
    }
    comp_err_sum.assign(ids.size(), 0);
    comp_err_cnt.assign(ids.size(), 0);
    const size_t nc = static_cast<size_t>(num_comp);
    comp_size.assign(nc, 0);
    for (int x : comp) ++comp_size[static_cast<size_t>(x)];
    comp_centroid.assign(nc, Eigen::Vector3f::Zero());
    for (size_t i = 0; i < samples.size(); ++i)
      comp_centroid[static_cast<size_t>(comp[i])] += metrics::SamplePosition(truth, samples[i]);
    for (size_t c = 0; c < nc; ++c) comp_centroid[c] /= static_cast<float>(std::max<size_t>(1, comp_size[c]));
    prev.assign(2, {});
    sum.assign(2, std::vector<double>(nc, 0));
    cnt = valid = abs_d = hid_sum = hid_cnt = sum;
    speed_sum.assign(nc, 0);
    frames_seen.assign(2, 0);
    near_nodes.assign(nc, 0);
    near_failed = near_res = near_viol = near_stretch = near_affine = near_low_support = near_nodes;
    timeline.assign(nc, {});
  }
  void Add(int mode, const Mesh& recon, const Mesh& truth, const TemporalFusion* fusion, const TemporalFrameStats* st) {
    const size_t md = static_cast<size_t>(mode);
    const size_t nc = static_cast<size_t>(num_comp);
    metrics::FlickerOptions fo;
    fo.num_threads = 2;
    auto d = metrics::ComputeNormalOffsets(recon, truth, samples, fo);
    if (!d.ok()) return;
    const std::vector<Eigen::Vector3f> pos = metrics::SamplePositions(truth, samples);
    frames_seen[md] += 1;
    std::vector<double> fs(nc, 0), fc(nc, 0);
    for (size_t i = 0; i < samples.size(); ++i) {
      const size_t c = static_cast<size_t>(comp[i]);
      if (!std::isnan((*d)[i])) {
        valid[md][c] += 1;
        abs_d[md][c] += std::abs((*d)[i]) * 1000;
      }
      if (mode == 0 && !prev_pos.empty()) speed_sum[c] += (pos[i] - prev_pos[i]).norm() * 1000;
    }
    if (!prev[md].empty())
      for (size_t i = 0; i < samples.size(); ++i) {
        const float a = prev[md][i], b = (*d)[i];
        if (std::isnan(a) || std::isnan(b)) continue;
        const size_t c = static_cast<size_t>(comp[i]);
        sum[md][c] += std::abs(b - a) * 1000;
        cnt[md][c] += 1;
        if (!visible.empty() && !prev_visible.empty() && !visible[i] && !prev_visible[i]) {
          hid_sum[md][c] += std::abs(b - a) * 1000;
          hid_cnt[md][c] += 1;
        }
        fs[c] += std::abs(b - a) * 1000;
        fc[c] += 1;
      }
    for (size_t c = 0; c < nc; ++c) {
      if (timeline[c].size() < static_cast<size_t>(frames_seen[md]))
        timeline[c].resize(static_cast<size_t>(frames_seen[md]), {NAN, NAN});
      timeline[c][static_cast<size_t>(frames_seen[md]) - 1][md] = fc[c] > 0 ? fs[c] / fc[c] : NAN;
    }
    prev[md] = *d;
    if (mode == 0) prev_pos = pos;
    if (mode == 1 && fusion != nullptr && st != nullptr) {
      char note[256];
      std::snprintf(note, sizeof(note), "tracked %d lost %d region_reset %d (%zu blocks) failed %d/%d (res %d viol %d stretch %d affine %d)",
                    st->tracked, st->lost, st->region_reset, st->reset_blocks, st->failed_nodes, st->nodes,
                    st->track.failed_residual, st->track.failed_violation, st->track.failed_stretch,
                    st->track.failed_affine);
      frame_notes.push_back(note);
      if (!st->tracked || st->track.nodes.size() != fusion->graph().num_nodes()) return;
      const DeformationGraph& g = fusion->graph();
      const TrackerOptions& to = fusion->options().tracker;
      const float r2 = 0.03f * 0.03f;
      for (size_t k = 0; k < g.num_nodes(); ++k) {
        const Eigen::Vector3f w = g.position(static_cast<int>(k)) + g.translation(static_cast<int>(k));
        std::vector<uint8_t> hit(nc, 0);
        for (size_t i = 0; i < pos.size(); ++i)
          if ((pos[i] - w).squaredNorm() < r2) hit[static_cast<size_t>(comp[i])] = 1;
        const NodeReport& nr = st->track.nodes[k];
        const float lo = 1.0f - to.fail_affine_scale;
        for (size_t c = 0; c < nc; ++c) {
          if (!hit[c]) continue;
          near_nodes[c] += 1;
          near_low_support[c] += nr.observed < to.min_support;
          if (!nr.failed) continue;
          near_failed[c] += 1;
          near_res[c] += nr.residual_m > to.fail_residual_m;
          near_viol[c] += nr.observed >= to.min_support && nr.violations > to.fail_violation_fraction * nr.observed;
          near_stretch[c] += nr.stretch_m > to.fail_stretch_factor * g.options().node_spacing_m;
          near_affine[c] += nr.scale_min < lo || nr.scale_max > 1.0f / lo;
        }
      }
    }
  }
  // Which samples some pod sees at this frame (noise-free depth within 15 mm,
  // front-facing); call before Add() of the frame's modes.
  void SetVisibility(const Rig& rig, const StudioGroundTruth& gt) {
    prev_visible = visible;
    const Mesh& m = gt.foreground_mesh;
    visible.assign(samples.size(), 0);
    for (size_t i = 0; i < samples.size(); ++i) {
      const Eigen::Vector3f p = metrics::SamplePosition(m, samples[i]);
      const auto& t = m.triangles[samples[i].triangle];
      const Eigen::Vector3f n = (m.positions[t[1]] - m.positions[t[0]]).cross(m.positions[t[2]] - m.positions[t[0]]);
      if (n.isZero()) continue;  // a degenerate triangle faces no pod
      for (size_t k = 0; k < rig.pods.size() && !visible[i]; ++k) visible[i] = PodSees(rig, gt, k, p, n) ? 1 : 0;
    }
  }
  void TrackError(const Mesh& truth, const TemporalFusion* fusion, const TemporalFrameStats& st) {
    if (!st.tracked || prev_truth.size() != truth.positions.size()) return;
    const DeformationGraph& g = fusion->graph();
    std::vector<float> en, ea;
    for (size_t k = 0; k < g.num_nodes(); ++k) {
      const Eigen::Vector3f& p = g.position(static_cast<int>(k));
      float best = 0.02f * 0.02f;
      int bi = -1;
      for (size_t v = 0; v < prev_truth.size(); ++v) {
        const float d = (prev_truth[v] - p).squaredNorm();
        if (d < best) {
          best = d;
          bi = static_cast<int>(v);
        }
      }
      if (bi < 0) continue;
      const size_t b = static_cast<size_t>(bi);
      const Eigen::Vector3f err = g.translation(static_cast<int>(k)) - (truth.positions[b] - prev_truth[b]);
      ea.push_back(err.norm() * 1000);
      if (truth.normals.size() == truth.positions.size()) {
        en.push_back(std::abs(err.dot(truth.normals[b])) * 1000);
        if (track_err.size() >= 9 && vertex_comp[b] >= 0) {
          comp_err_sum[static_cast<size_t>(vertex_comp[b])] += en.back();
          comp_err_cnt[static_cast<size_t>(vertex_comp[b])] += 1;
        }
      }
    }
    auto med = [](std::vector<float> v) {
      if (v.empty()) return NAN;
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return v[v.size() / 2];
    };
    auto mean = [](const std::vector<float>& v) {
      double a = 0;
      for (float x : v) a += x;
      return v.empty() ? NAN : a / static_cast<double>(v.size());
    };
    char buf[200];
    std::snprintf(buf, sizeof(buf), "nodes %zu matched %zu, error median %.2f mean %.2f mm, along normal median %.2f mean %.2f mm",
                  g.num_nodes(), ea.size(), med(ea), mean(ea), med(en), mean(en));
    track_err.push_back(buf);
  }
  void Print(const metrics::FlickerAccumulator& per_frame, const metrics::FlickerAccumulator& temporal) const {
    {
      double hs[2] = {0, 0}, hc[2] = {0, 0}, as[2] = {0, 0}, ac[2] = {0, 0};
      for (size_t md = 0; md < 2; ++md)
        for (size_t c = 0; c < static_cast<size_t>(num_comp); ++c) {
          hs[md] += hid_sum[md][c];
          hc[md] += hid_cnt[md][c];
          as[md] += sum[md][c];
          ac[md] += cnt[md][c];
        }
      spdlog::info(
          "diag samples seen by no pod: {:.1f} % of valid pairs (per_frame) / {:.1f} % (temporal); their flicker "
          "{:.2f} / {:.2f} mm; seen samples {:.2f} / {:.2f} mm",
          100 * hc[0] / std::max(1.0, ac[0]), 100 * hc[1] / std::max(1.0, ac[1]), hs[0] / std::max(1.0, hc[0]),
          hs[1] / std::max(1.0, hc[1]), (as[0] - hs[0]) / std::max(1.0, ac[0] - hc[0]),
          (as[1] - hs[1]) / std::max(1.0, ac[1] - hc[1]));
      for (size_t c = 0; c < static_cast<size_t>(num_comp); ++c)
        spdlog::info("diag component {} hidden: {:.0f} % of pairs, flicker {:.2f} / {:.2f} mm; seen {:.2f} / {:.2f} mm",
                     c, 100 * hid_cnt[0][c] / std::max(1.0, cnt[0][c]), hid_sum[0][c] / std::max(1.0, hid_cnt[0][c]),
                     hid_sum[1][c] / std::max(1.0, hid_cnt[1][c]),
                     (sum[0][c] - hid_sum[0][c]) / std::max(1.0, cnt[0][c] - hid_cnt[0][c]),
                     (sum[1][c] - hid_sum[1][c]) / std::max(1.0, cnt[1][c] - hid_cnt[1][c]));
    }
    std::string pairs_line = "diag flicker per frame pair (per_frame/temporal mm):";
    for (size_t i = 0; i < per_frame.pairs().size() && i < temporal.pairs().size(); ++i)
      pairs_line +=
          fmt::format(" f{} {:.2f}/{:.2f}", i + 1, per_frame.pairs()[i].flicker_mm, temporal.pairs()[i].flicker_mm);
    spdlog::info("{}", pairs_line);
    const double nf = std::max(1.0, frames_seen[1] - 1);
    for (int ci = 0; ci < num_comp; ++ci) {
      const size_t c = static_cast<size_t>(ci);
      spdlog::info(
          "diag component {}: {} samples at ({:.2f} {:.2f} {:.2f}), flicker per_frame {:.2f} temporal {:.2f} mm; "
          "valid/frame {:.0f} / {:.0f}; "
          "mean |d| {:.2f} / {:.2f} mm; truth speed {:.1f} mm/frame; temporal nodes near/frame {:.1f} failed {:.2f} "
          "(res {:.2f} viol {:.2f} stretch {:.2f} affine {:.2f}) unsupported {:.2f}",
          ci, comp_size[c], comp_centroid[c].x(), comp_centroid[c].y(), comp_centroid[c].z(),
          sum[0][c] / std::max(1.0, cnt[0][c]), sum[1][c] / std::max(1.0, cnt[1][c]),
          valid[0][c] / std::max(1.0, frames_seen[0]), valid[1][c] / std::max(1.0, frames_seen[1]),
          abs_d[0][c] / std::max(1.0, valid[0][c]), abs_d[1][c] / std::max(1.0, valid[1][c]),
          speed_sum[c] / std::max(1.0, frames_seen[0] - 1) / static_cast<double>(comp_size[c]), near_nodes[c] / nf,
          near_failed[c] / nf, near_res[c] / nf, near_viol[c] / nf, near_stretch[c] / nf, near_affine[c] / nf,
          near_low_support[c] / nf);
    }
    // Timelines of the small components (< 500 samples).
    for (int ci = 0; ci < num_comp; ++ci) {
      const size_t c = static_cast<size_t>(ci);
      if (comp_size[c] >= 500) continue;
      std::string line = fmt::format("diag timeline component {} (per_frame/temporal mm):", ci);
      for (size_t f = 1; f < timeline[c].size(); ++f)
        line += fmt::format(" f{} {:.1f}/{:.1f}", f, timeline[c][f][0], timeline[c][f][1]);
      spdlog::info("{}", line);
    }
    for (size_t f = 0; f < frame_notes.size(); ++f) spdlog::info("diag frame {}: {}", f, frame_notes[f]);
    for (size_t c = 0; c < comp_err_sum.size(); ++c)
      spdlog::info("diag component {}: node error along normal (frames 10+) mean {:.2f} mm over {:.0f} node-frames", c,
                   comp_err_sum[c] / std::max(1.0, comp_err_cnt[c]), comp_err_cnt[c]);
    for (size_t f = 0; f < track_err.size(); ++f) spdlog::info("diag track error frame {}: {}", f + 1, track_err[f]);
  }
};

int RunTemporal(const BenchArgs& args, const Extra& extra) {
  auto workload = GetWorkload(args.workload);
  if (!workload.ok()) {
    spdlog::error("temporal: {}", workload.status().ToString());
    return 2;
  }
  auto solver = ParseTrackerSolver(extra.solver);
  if (!solver.ok()) {
    spdlog::error("temporal: {}", solver.status().ToString());
    return 2;
  }
  const Rig& rig = workload->rig;
  if (extra.drop_pod >= static_cast<int>(rig.pods.size())) {
    spdlog::error("temporal: --drop-pod {} but the rig has {} pods", extra.drop_pod, rig.pods.size());
    return 2;
  }
  const int frames = args.frames > 0 ? args.frames : 30;
  StudioOptions so = workload->studio;
  so.threads = 2;
  auto studio = SyntheticStudio::Create(rig, so);
  if (!studio.ok()) {
    spdlog::error("temporal: {}", studio.status().ToString());
    return 1;
  }

  TemporalFusionOptions base;
  base.tsdf.voxel_size = workload->voxel_size_m;
  base.tsdf.threads = 2;
  base.tracker.threads = 2;
  base.tracker.solver = *solver;
  if (extra.spacing_cm > 0) base.graph.node_spacing_m = static_cast<float>(extra.spacing_cm / 100);
  if (extra.max_weight > 0) base.max_weight = static_cast<float>(extra.max_weight);
  if (extra.track_points > 0) base.track_points = extra.track_points;
  if (extra.points_per_node >= 0) base.min_points_per_node = static_cast<float>(extra.points_per_node);
  if (extra.reg_weight >= 0) base.tracker.regularization_weight = static_cast<float>(extra.reg_weight);
  if (extra.rot_weight >= 0) base.tracker.rotation_weight = static_cast<float>(extra.rot_weight);
  if (extra.hull_weight >= 0) base.tracker.hull_weight = static_cast<float>(extra.hull_weight);
  base.predict_motion = extra.predict;
  if (extra.sparse >= 0) base.tracker.use_sparse = extra.sparse != 0 ? 1 : 0;
  if (extra.sparse_weight >= 0) base.tracker.sparse_weight = static_cast<float>(extra.sparse_weight);
  if (extra.parallel_pcg >= 0) base.tracker.parallel_pcg = extra.parallel_pcg != 0;
  if (extra.pcg > 0) base.tracker.pcg_max_iterations = extra.pcg;
  if (extra.data_window >= -1) base.tracker.data_window_px = extra.data_window;
  if (extra.snap_mm >= 0) base.snap_still_m = static_cast<float>(extra.snap_mm / 1000);
  if (extra.iterations >= 0) base.tracker.iterations = extra.iterations;
  if (extra.rigid_iterations >= 0) base.tracker.rigid_iterations = extra.rigid_iterations;
  if (extra.normal_radius >= 0) base.track_normal_radius_voxels = extra.normal_radius;
  if (extra.min_track_weight >= 0) base.min_track_weight = static_cast<float>(extra.min_track_weight);
  if (extra.fail_residual_mm > 0) base.tracker.fail_residual_m = static_cast<float>(extra.fail_residual_mm / 1000);

  std::vector<TemporalRun> runs(extra.drop_pod >= 0 ? 4 : 2);
  const char* names[4] = {"per_frame", "temporal", "per_frame_dropped", "temporal_dropped"};
  for (size_t r = 0; r < runs.size(); ++r) {
    runs[r].mode = names[r];
    TemporalFusionOptions o = base;
    o.temporal = r % 2 == 1;
    auto f = TemporalFusion::Create(o);
    if (!f.ok()) {
      spdlog::error("temporal: {}", f.status().ToString());
      return 2;
    }
    runs[r].fusion = std::move(*f);
  }

  const bool diag_on = std::getenv("HOLO_TEMPORAL_DIAG") != nullptr;
  Diag diag;
  RgbdFrameSet set, dropped;
  StudioGroundTruth gt;
  metrics::MeshDistanceOptions mdo;
  mdo.num_threads = 2;
  for (int f = 0; f < frames; ++f) {
    (*studio)->RenderFrame(extra.still ? 0 : f, &set, &gt);
    for (size_t k = 0; k < set.frames.size(); ++k) set.frames[k].mask = gt.mask[k];
    const bool eval = f % extra.eval_every == extra.eval_every - 1;
    if (diag_on && f == 0) diag.Init(gt.foreground_mesh);
    if (diag_on) {
      diag.SetVisibility(rig, gt);
      diag.prev_truth = diag.cur_truth;
      diag.cur_truth = gt.foreground_mesh.positions;
    }
    std::vector<Eigen::Vector3f> exclusive;
    if (extra.drop_pod >= 0 && f >= extra.drop_from) {
      dropped = set;
      dropped.frames[static_cast<size_t>(extra.drop_pod)].depth.Fill(0);
      dropped.frames[static_cast<size_t>(extra.drop_pod)].mask.Fill(0);
      exclusive = ExclusiveVertices(rig, gt, extra.drop_pod);
    }
    for (size_t r = 0; r < runs.size(); ++r) {
      TemporalRun& run = runs[r];
      const RgbdFrameSet& in = (r >= 2 && f >= extra.drop_from) ? dropped : set;
      TemporalFrameStats st;
      const double cpu0 = ProcessCpuMs();
      if (Status s = run.fusion->Process(rig, in, &run.mesh, &st); !s.ok()) {
        spdlog::error("temporal: {} frame {}: {}", run.mode, f, s.ToString());
        return 1;
      }
      const double cpu = ProcessCpuMs() - cpu0;
      if (r < 2) {
        if (Status s = run.flicker.Add(run.mesh, gt.foreground_mesh); !s.ok()) {
          spdlog::error("temporal: flicker: {}", s.ToString());
          return 1;
        }
        if (f > 0) {  // frame 0 is per-frame fusion in both modes
          run.track_ms.push_back(st.track_ms);
          run.warp_ms.push_back(st.warp_ms);
          run.fuse_ms.push_back(st.fuse_ms + st.warp_ms);
          run.mesh_ms.push_back(st.mesh_ms);
          run.total_ms.push_back(st.total_ms);
          run.cpu_ms.push_back(cpu);
        }
        if (diag_on) diag.Add(static_cast<int>(r), run.mesh, gt.foreground_mesh, run.fusion.get(), &st);
        if (diag_on && r == 1) diag.TrackError(gt.foreground_mesh, run.fusion.get(), st);
        if (eval && !run.mesh.empty()) {
          auto d = metrics::ComputeMeshDistance(run.mesh, gt.foreground_mesh, mdo);
          if (d.ok()) {
            auto ti = diag_on ? metrics::TriangleIndex::Build(gt.foreground_mesh)
                              : StatusOr<metrics::TriangleIndex>(InvalidArgument("diagnostics off"));
            if (ti.ok()) {
              const std::vector<float> dd = ti->DistanceBatch(run.mesh.positions, 1.0f, 2);
              int hist[6] = {0, 0, 0, 0, 0, 0};
              double sums[6] = {0, 0, 0, 0, 0, 0};
              const float edges[6] = {0.005f, 0.01f, 0.02f, 0.05f, 0.1f, 1e9f};
              for (float x : dd)
                for (int b = 0; b < 6; ++b)
                  if (x < edges[b]) {
                    ++hist[b];
                    sums[b] += x;
                    break;
                  }
              std::string line = fmt::format(
                  "diag {} f{} verts {}: <5mm {} <10 {} <20 {} <50 {} <100 {} more {}; sum-mm share:", run.mode, f,
                  dd.size(), hist[0], hist[1], hist[2], hist[3], hist[4], hist[5]);
              double tot = 0;
              for (double x : sums) tot += x;
              for (double x : sums) line += fmt::format(" {:.2f}", x / tot);
              spdlog::info("{}", line);
            }
            if (diag_on)
              spdlog::info("diag {} f{} chamfer {:.2f} accuracy {:.2f} completeness {:.3f}", run.mode, f, d->chamfer_mm,
                           d->accuracy_mm, d->completeness);
            run.chamfer.push_back(d->chamfer_mm);
            run.completeness.push_back(d->completeness);
            run.accuracy.push_back(d->accuracy_mm);
          }
        }
      } else if (!exclusive.empty()) {
        run.exclusive.push_back(FractionWithin(run.mesh, exclusive, 0.01f));
      }
      if (r == 1 && extra.drop_pod >= 0 && f >= extra.drop_from && !exclusive.empty()) {
        runs[0].exclusive.push_back(FractionWithin(runs[0].mesh, exclusive, 0.01f));
        runs[1].exclusive.push_back(FractionWithin(runs[1].mesh, exclusive, 0.01f));
      }
      if (std::getenv("HOLO_TEMPORAL_VERBOSE") && st.tracked)
        spdlog::info(
            "{} f{}: nodes {} failed {} (res {} viol {} stretch {}) rms {:.2f} mm assoc {}/{} track {:.1f} (rigid "
            "{:.1f} assoc {:.1f} solve {:.1f} pcg {} it {} step {:.2f} mm) warp {:.1f} fuse {:.1f} mesh {:.1f} carried "
            "{} reset {} hull {} features {:.1f} ms {} pairs rms {:.1f} mm",
            run.mode, f, st.nodes, st.failed_nodes, st.track.failed_residual, st.track.failed_violation,
            st.track.failed_stretch, st.track.data_rms_m * 1000, st.track.associated_points, st.track.num_points,
            st.track_ms, st.track.rigid_ms, st.track.associate_ms, st.track.solve_ms, st.track.pcg_iterations,
            st.track.iterations, st.track.last_step_m * 1000, st.warp_ms, st.fuse_ms, st.mesh_ms, st.carried_blocks,
            st.reset_blocks, st.hull_blocks, st.features_ms, st.feature_pairs, st.track.sparse_rms_m * 1000);
      run.tracked += st.tracked;
      run.nodes += st.nodes;
      run.failed_nodes += st.failed_nodes;
      run.region_resets += st.region_reset;
      run.full_resets += st.full_reset;
      run.lost += st.lost;
      run.resets += st.region_reset || st.full_reset;
    }
    if (!args.json && ((f + 1) % 10 == 0 || f + 1 == frames)) spdlog::info("temporal: frame {}/{}", f + 1, frames);
  }
  if (diag_on) diag.Print(runs[0].flicker, runs[1].flicker);

  const std::string w = args.workload;
  std::map<std::string, std::string> q;
  q["solver"] = extra.solver;
  q["masks"] = "truth";
  q["frames"] = std::to_string(frames);
  for (size_t r = 0; r < 2; ++r) {
    TemporalRun& run = runs[r];
    auto qm = q;
    qm["mode"] = run.mode;
    qm["content"] = r % 2 == 1 ? "temporal" : "fused";
    auto stage = [&](const char* name, const std::vector<double>& v) {
      auto qs = qm;
      qs["stage"] = name;
      EmitFigure("temporal", w, "ms", Median(v), "ms", qs);
    };
    if (r == 1) stage("track", run.track_ms);
    if (r == 1) stage("warp", run.warp_ms);
    stage("fuse", run.fuse_ms);
    stage("mesh", run.mesh_ms);
    stage("total", run.total_ms);
    auto qc = qm;
    qc["stage"] = "total";
    EmitFigure("temporal", w, "cpu_ms", Median(run.cpu_ms), "ms", qc);
    EmitFigure("temporal", w, "fps", 1000.0 / std::max(1e-9, Median(run.total_ms)), "1/s", qm);
    EmitFigure("temporal", w, "flicker_mm", run.flicker.Mean(), "mm", qm);
    EmitFigure("temporal", w, "chamfer_mm", Mean(run.chamfer), "mm", qm);
    EmitFigure("temporal", w, "completeness", Mean(run.completeness), "1", qm);
    EmitFigure("temporal", w, "accuracy_mm", Mean(run.accuracy), "mm", qm);
    if (r == 1) {
      EmitFigure("temporal", w, "resets", run.resets, "frames", qm);
      EmitFigure("temporal", w, "full_resets", run.full_resets, "frames", qm);
      EmitFigure("temporal", w, "lost_frames", run.lost, "frames", qm);
      EmitFigure("temporal", w, "nodes", run.tracked ? run.nodes / run.tracked : 0, "1", qm);
      EmitFigure("temporal", w, "failed_nodes", run.tracked ? run.failed_nodes / run.tracked : 0, "1", qm);
    }
  }
  EmitFigure("temporal", w, "flicker_ratio", runs[1].flicker.Mean() / runs[0].flicker.Mean(), "1", q);
  if (runs.size() == 4) {
    auto qd = q;
    qd["dropped_pod"] = std::to_string(extra.drop_pod);
    qd["drop_from"] = std::to_string(extra.drop_from);
    const char* modes[4] = {"per_frame", "temporal", "per_frame", "temporal"};
    for (size_t r = 0; r < 4; ++r) {
      auto qe = qd;
      qe["mode"] = modes[r];
      qe["pods"] = r < 2 ? "all" : "dropped";
      EmitFigure("temporal", w, "exclusive_completeness", Mean(runs[r].exclusive), "1", qe);
    }
    auto qe = qd;
    qe["mode"] = "temporal";
    qe["pods"] = "dropped";
    EmitFigure("temporal", w, "resets", runs[3].resets, "frames", qe);
  }
  return 0;
}

}  // namespace

BenchFn SetupTemporal(CLI::App& app) {
  DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto extra = std::make_shared<Extra>();
  DeclareOptions(app, extra.get());
  return [extra](const BenchArgs& args) { return RunTemporal(args, *extra); };
}

HOLO_REGISTER_BENCH_OPTIONS("temporal",
                            "per-frame vs temporal fusion (non-rigid ED tracking): ms per stage, fps, flicker, Chamfer, "
                            "completeness, resets; a dropped pod's exclusive surface",
                            SetupTemporal);

}  // namespace holo::bench
