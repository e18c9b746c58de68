// holoport-bench codecs --workload S8-QVGA|S8-VGA [--json] [--frames N] [--repeats N] [--synthetic]
//                       [--only=G0,G1,...] [--jpeg-quality=Q] [--chroma444|--chroma420] [--chroma-shift=S]
//                       [--fill-pad|--fill-push-pull|--fill-mean] [--fast-dct] [--quant-standard]
//                       [--no-optimize-huffman] [--no-pack]
//                       [--mask-zstd-level=L] [--huffman-refresh=N] [--peer-jpeg-quality=Q] [--hash]
//                       [--content fused|temporal|truth] [--full-mesh] [--video=x264-444,x264-420,vpx-vp9-444,vpx-vp9-420[@CRF],...]
//                       [--video-crf=N] [--video-preset=P] [--keyframe-interval=N]
//                       [--g2-step-mm=S] [--g2-max-rms-mm=R] [--g2-keyframe-step-mm=S] [--g2-dead-zone=Z] [--g2-group=N]
//                       [--g2-smooth=N] [--g2-max-disp-mm=D] [--g2-far-fraction=F] [--g2-no-backoff]
//                       [--g3-step-mm=S]
// Unknown options are refused (exit 2); --name value and --name=value both work.
//
// --content truth (the default): the studio's ground-truth foreground mesh and
// the pods' images with exact masks, frames 0, 1, 2, ... (consecutive, as a
// video codec sees them). --content fused: the real capture site run
// in-process (CaptureSite, MaskSource::kSegment, background learned from the
// empty room, the workload's voxel size): the site's fused, textured mesh —
// the compact stream mesh the live server sends (StreamMeshOptions defaults:
// every 2nd voxel, the workload's triangle budget, 10 k per person;
// qualifier mesh "site-stream"), or with
// --full-mesh the full-resolution one ("site-fused") — and the pods' images
// with the site's own segmentation masks. Default frames:
// 4 on truth, 60 on fused (a video codec needs a sequence; --frames N).
//
// Video colour (V1, protocol/video_codec.h) runs as codec "video" with a
// `library` and `chroma` qualifier, one encoder and one decoder per pod over
// the frame sequence (fresh ones per repeat); its bytes are the mean over the
// sequence (keyframes included), its times the median per frame of all pods.
// G3 (protocol/surface_codec.h) codes the grid the stream mesh is extracted
// from (fused and temporal content with the stream mesh only); its error is
// the two-sided surface distance to the site's stream mesh of the same frame
// (`geom_surface_rms_mm`, as for G2), and `triangles` is what the viewer gets.
// Between consecutive frames G3 also reports what an inter-frame code could
// predict (FrameToFrame): `repeat_label_fraction`, `repeat_case_fraction`,
// `repeat_crossing_fraction`, `crossing_shift_mm` p50/p90 and
// `crossing_within_step_fraction`.
//
// (--hash prints a hash of every geometry blob, and of every V1 blob and its
// decoded picture, of the first repeat to stderr;
// --peer-jpeg-quality sets the jpeg-box peer's TurboJPEG quality, default 90.)
//
// Times are medians over frames × repeats, wall (`encode_ms`) and thread CPU
// (`encode_cpu_ms`, robust to other load on a shared machine). G1 runs as
// "G1" (defaults: normals recomputed by the decoder, chroma quantized),
// "G1-normals" (normals sent) and "G1-lossless-color"; normal errors are
// angles to the input's normals, and "area-weighted-unquantized" shows how
// much of that is the method rather than the quantization.
//
// G2 (temporal geometry, protocol/geometry2_codec.h) runs as codec "G2": one
// encoder and one decoder over the sequence; bytes are the mean (keyframes
// included), `keyframe_ratio` the share of keyframes, `geom_rms_mm` the mean
// over frames of the two-sided point-to-surface RMS between the decoded mesh
// and the site's mesh (G2 keeps the keyframe's vertices, so a vertex map does
// not apply); G1 reports the same measure as `geom_surface_rms_mm`.
//
// Depth codecs D1 and D2 (PROTOCOL.md §8) on every pod's depth image of the
// truth content (the studio's noisy pod depth, as holoport-pod sends it),
// figures per pod frame, qualifier content "studio-pod-depth"; `pod_mbps` adds
// the pod's colour as holoport-pod sends it (C1 quality 60, no mask) and the
// PodFrame message: a pod's stream at 30 fps. (--only=D1,D2 runs just these.)
//
// Geometry codecs G0 (Holoportation's fp16 + LZ4 baseline) and G1 (ours),
// Draco side by side in the same process on the same meshes at comparable
// quantization (position step ≤ 1 mm), and colour codecs C0 and C1 on the
// same per-pod masked images. One core; data prepared outside the timed code.
//
// Input: the synthetic studio's frames (ground-truth foreground mesh and
// per-pod colour + exact mask) when the studio is compiled in; otherwise, or
// with --synthetic, workload "synthetic-sphere": a bumpy noisy blob extracted
// by marching tetrahedra at 6 mm voxels (vertices on lattice edges, irregular
// connectivity, like a TSDF mesh of one person, ~60k vertices) and 8 masked
// textured images at the workload's resolution.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <turbojpeg.h>

#include "bench.h"
#include "common/clock.h"
#include "common/image.h"
#include "common/log.h"
#include "common/mesh.h"
#include "protocol/color_codec.h"
#include "protocol/depth_codec.h"
#include "protocol/draco_peer.h"
#include "common/metrics/mesh_shapes.h"
#include "common/metrics/triangle_index.h"
#include "protocol/geometry2_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/surface_codec.h"
#include "common/quantile.h"
#include "protocol/video_codec.h"

#if __has_include("studio/workloads.h") && __has_include("studio/studio.cc")
#define HOLO_BENCH_HAVE_STUDIO 1
#include "server/pipeline/capture_site.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#else
#define HOLO_BENCH_HAVE_STUDIO 0
#endif

namespace holo::bench {
namespace {

using protocol::ColorCodec;
using protocol::GeometryCodec;

double NowMs() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The benchmark's own options (see the comment at the top; CLI11 takes
// "--name value" and "--name=value").
struct CodecsOptions {
  bool synthetic = false, hash = false;
  bool full_mesh = false;  // fused: the full-resolution mesh, not the stream mesh the live server sends
  int stream_step = holo::StreamMeshOptions{}.step;  // fused: the stream mesh's grid step in voxels (holoport-server --stream-step)
  std::string only;                         // "G1,C1": only these codecs
  std::string content = "truth";            // truth | fused
  std::string video = "x264-444,x264-420";  // V1 runs, LABEL[@CRF],...
  int video_crf = -1;                       // -1: the encoder's default
  std::string video_preset;                 // "": the library's default
  std::string video_mask = "blocks";        // V1 mask format: blocks | rows
  std::string video_window = "on";          // V1 picture: a window around the foreground (on) or the whole image
  std::optional<int> keyframe_interval;     // unset: VideoEncodeOptions' default
  std::optional<int> chroma_shift;          // unset: GeometryEncodeOptions' default
  // C1 options (unset: ColorEncodeOptions' defaults).
  std::optional<int> jpeg_quality, mask_zstd_level, huffman_refresh;
  bool chroma444 = false, chroma420 = false, fill_pad = false, fill_push_pull = false, fill_mean = false;
  bool fast_dct = false, quant_standard = false, no_optimize_huffman = false, no_pack = false;
  int peer_jpeg_quality = 90;  // the jpeg-box peer's TurboJPEG quality
  // G2 options (unset: Geometry2EncodeOptions' defaults), millimetres.
  std::optional<float> g2_step_mm, g2_max_rms_mm, g2_keyframe_step_mm, g2_dead_zone;
  std::optional<int> g2_group, g2_smooth;
  bool g2_no_backoff = false;
  std::optional<float> g2_max_disp_mm, g2_far_fraction;
  std::optional<float> g3_step_mm;  // G3 value step (unset: SurfaceEncodeOptions' default)
};

struct PodImageInput {
  ImageRgb8 color;
  ImageGray8 mask;
  ImageDepth16 depth;  // the pod's depth as it sends it (studio truth content only)
};

struct FrameInput {
  Mesh mesh;
  SdfGrid field;  // fused stream mesh: the grid it was extracted from (G3)
  std::vector<PodImageInput> pods;
};

// What a grid repeats from the previous frame's, at the same world samples
// (the site's grids sit on one lattice: their origins differ by whole
// samples; grids that do not are skipped): what an inter-frame code of G3's
// labels and crossings could predict. Labels as G3 has them: a sample is
// labelled (inside or outside) when it is a corner of a surface cube (eight
// observed corners, a sign change; G3 also drops small pieces, not done
// here). Figures: of the samples labelled in either frame, those with the
// same label in both; of the current surface cubes, those whose cube in the
// previous grid has the same marching-cubes case; of the current crossed
// edges, those crossed the same way before, and how far the crossing moved.
struct GridRepeat {
  size_t labelled = 0, same_label = 0, cubes = 0, same_case = 0, edges = 0, edges_alike = 0;
  std::vector<double> shift_mm;
  GridRepeat& operator+=(const GridRepeat& r) {
    labelled += r.labelled;
    same_label += r.same_label;
    cubes += r.cubes;
    same_case += r.same_case;
    edges += r.edges;
    edges_alike += r.edges_alike;
    shift_mm.insert(shift_mm.end(), r.shift_mm.begin(), r.shift_mm.end());
    return *this;
  }
};
// A grid with its G3-style labels and cube cases (SurfaceLabels).
struct LabelledGrid {
  const SdfGrid* grid = nullptr;
  std::vector<uint8_t> labels;
  std::vector<int16_t> codes;
};
// Per sample: 0 unlabelled, 1 outside, 2 inside; `codes` per cube origin: its
// marching-cubes case, or -1 when it is not a surface cube.
void SurfaceLabels(const SdfGrid& g, std::vector<uint8_t>* labels, std::vector<int16_t>* codes) {
  labels->assign(g.size(), 0);
  codes->assign(g.size(), -1);
  for (int z = 0; z + 1 < g.nz; ++z)
    for (int y = 0; y + 1 < g.ny; ++y)
      for (int x = 0; x + 1 < g.nx; ++x) {
        int code = 0;
        bool ok = true;
        for (int c = 0; c < 8 && ok; ++c) {
          const float v = g.sdf[g.Index(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2))];
          ok = v == v;
          code |= (v < 0) << c;
        }
        if (!ok || code == 0 || code == 255) continue;
        (*codes)[g.Index(x, y, z)] = static_cast<int16_t>(code);
        for (int c = 0; c < 8; ++c)
          (*labels)[g.Index(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2))] = (code >> c) & 1 ? 2 : 1;
      }
}
GridRepeat FrameToFrame(const LabelledGrid& before, const LabelledGrid& now) {
  const SdfGrid &prev = *before.grid, &cur = *now.grid;
  const std::vector<uint8_t>&lp = before.labels, &lc = now.labels;
  const std::vector<int16_t>&cp = before.codes, &cc = now.codes;
  GridRepeat r;
  if (std::abs(prev.voxel_m - cur.voxel_m) > 1e-6f * cur.voxel_m) return r;
  int d[3];
  for (int a = 0; a < 3; ++a) {
    const double off = (static_cast<double>(cur.origin[a]) - prev.origin[a]) / cur.voxel_m;
    d[a] = static_cast<int>(std::lround(off));
    if (std::abs(off - d[a]) > 1e-3) return r;  // not on one lattice
  }
  // The previous grid's index of the current sample (x, y, z), or -1 outside it.
  auto prev_index = [&](int x, int y, int z) -> int64_t {
    const int X = x + d[0], Y = y + d[1], Z = z + d[2];
    if (X < 0 || Y < 0 || Z < 0 || X >= prev.nx || Y >= prev.ny || Z >= prev.nz) return -1;
    return static_cast<int64_t>(prev.Index(X, Y, Z));
  };
  size_t prev_labelled_seen = 0;  // previous labels that fall inside the current grid
  for (int z = 0; z < cur.nz; ++z)
    for (int y = 0; y < cur.ny; ++y)
      for (int x = 0; x < cur.nx; ++x) {
        const size_t i = cur.Index(x, y, z);
        const int64_t j = prev_index(x, y, z);
        const uint8_t a = lc[i], b = j >= 0 ? lp[static_cast<size_t>(j)] : 0;
        prev_labelled_seen += b != 0;
        if (a || b) {
          ++r.labelled;
          r.same_label += a == b;
        }
        if (cc[i] >= 0) {
          ++r.cubes;
          r.same_case += j >= 0 && cp[static_cast<size_t>(j)] == cc[i];
        }
        if (!a) continue;
        for (int axis = 0; axis < 3; ++axis) {
          const int p[3] = {x + (axis == 0), y + (axis == 1), z + (axis == 2)};
          if (p[0] >= cur.nx || p[1] >= cur.ny || p[2] >= cur.nz) continue;
          const size_t i1 = cur.Index(p[0], p[1], p[2]);
          if (!lc[i1] || lc[i1] == a) continue;  // not a crossed edge of a surface cube
          ++r.edges;
          const int64_t j1 = prev_index(p[0], p[1], p[2]);
          if (j < 0 || j1 < 0 || lp[static_cast<size_t>(j)] != a || lp[static_cast<size_t>(j1)] != lc[i1]) continue;
          ++r.edges_alike;
          const double v0 = cur.sdf[i], v1 = cur.sdf[i1];
          const double u0 = prev.sdf[static_cast<size_t>(j)], u1 = prev.sdf[static_cast<size_t>(j1)];
          r.shift_mm.push_back(std::abs(v0 / (v0 - v1) - u0 / (u0 - u1)) * cur.voxel_m * 1000.0);
        }
      }
  // Labels of the previous frame outside the current grid were lost.
  size_t prev_labelled = 0;
  for (uint8_t b : lp) prev_labelled += b != 0;
  r.labelled += prev_labelled - prev_labelled_seen;
  return r;
}

// ------------------------------------------------------------ synthetic input

// Smooth value noise on a 3 cm lattice, amplitude ±1.
struct ValueNoise {
  explicit ValueNoise(uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1, 1);
    for (float& v : table) v = u(rng);
  }
  float operator()(const Eigen::Vector3f& p) const {
    const Eigen::Vector3f q = p / 0.03f;
    const Eigen::Vector3f f = q.array().floor();
    const Eigen::Vector3f t = q - f;
    float r = 0;
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
      const uint32_t h = (static_cast<uint32_t>(static_cast<int>(f.x()) + dx) * 73856093u) ^
                         (static_cast<uint32_t>(static_cast<int>(f.y()) + dy) * 19349663u) ^
                         (static_cast<uint32_t>(static_cast<int>(f.z()) + dz) * 83492791u);
      const float w = (dx ? t.x() : 1 - t.x()) * (dy ? t.y() : 1 - t.y()) * (dz ? t.z() : 1 - t.z());
      r += w * table[h & 4095];
    }
    return r;
  }
  float table[4096];
};

// Marching tetrahedra over a signed distance function sampled at `voxel`.
Mesh SyntheticBlob(int frame, float voxel) {
  const Eigen::Vector3f center(0.1f, -0.2f, 1.0f);
  const float radius = 0.2f;
  const ValueNoise smooth(7 + frame), fine(1000 + frame);
  const float phase = 0.2f * frame;
  auto sdf = [&](const Eigen::Vector3f& p) {
    const Eigen::Vector3f d = p - center;
    const float r = d.norm();
    const float bumps = 0.04f * std::sin(4 * std::atan2(d.y(), d.x()) + phase) * d.z() / (r + 1e-6f);
    return r - radius * (1 + bumps) + 0.004f * smooth(p) + 0.0008f * fine(p * 5.0f);
  };
  const float half = radius * 1.3f;
  const Eigen::Vector3f lo = center - Eigen::Vector3f::Constant(half);
  const int n = static_cast<int>(std::ceil(2 * half / voxel)) + 1;
  const ValueNoise tint(99 + frame);
  return metrics::MakeSdfMesh(sdf, lo, Eigen::Vector3i::Constant(n), voxel,
                              [&](const Eigen::Vector3f& p, uint32_t) -> std::array<uint8_t, 3> {
                                const float t = 0.5f + 0.5f * tint(p * 0.5f);
                                return {static_cast<uint8_t>(90 + 120 * t),
                                        static_cast<uint8_t>(60 + 80 * (p.z() - lo.z()) / (2 * half)),
                                        static_cast<uint8_t>(150 - 90 * t)};
                              });
}

// A person-sized textured silhouette (ellipse + head) with mild sensor noise.
PodImageInput SyntheticPodImage(int w, int h, int pod, int frame) {
  std::mt19937 rng(static_cast<uint32_t>(pod * 1000 + frame));
  std::normal_distribution<float> noise(0, 1.5f);
  PodImageInput in;
  in.color.Resize(w, h);
  in.mask.Resize(w, h);
  const float cx = w * (0.45f + 0.02f * pod), cy = h * 0.58f;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float bx = (x - cx) / (0.16f * w), by = (y - cy) / (0.36f * h);
      const float hx = (x - cx) / (0.07f * w), hy = (y - h * 0.17f) / (0.09f * h);
      const bool fg = bx * bx + by * by < 1 || hx * hx + hy * hy < 1;
      in.mask.at(x, y) = fg ? 255 : 0;
      const float stripes = 40 * std::sin(0.08f * x + 0.05f * y + pod) + 25 * std::sin(0.21f * y);
      const float base[3] = {fg ? 150.f : 70.f, fg ? 110.f : 80.f, fg ? 90.f : 95.f};
      for (int c = 0; c < 3; ++c) {
        in.color.at(x, y, c) =
            static_cast<uint8_t>(std::clamp(base[c] + (fg ? stripes * (c == 0 ? 1 : 0.5f) : 0) + noise(rng), 0.f, 255.f));
      }
    }
  return in;
}

// ------------------------------------------------------------ metrics

struct GeomError {
  double rms_mm = 0, max_mm = 0;
  // Angle between input and decoded normals (-1 when either has none).
  double normal_mean_deg = -1, normal_p99_deg = -1, normal_max_deg = -1;
  double color_psnr_db = -1;  // vertex colours (RGB), capped at 99 dB; -1 without colours
};

GeomError ErrorByMap(const Mesh& in, const Mesh& out, const std::vector<uint32_t>& map) {
  double sum = 0, mx = 0;
  size_t n = 0;
  std::vector<double> angles;
  const bool normals = !in.normals.empty() && !out.normals.empty();
  for (size_t i = 0; i < in.num_vertices(); ++i) {
    if (map[i] == UINT32_MAX) continue;
    const double d = (in.positions[i] - out.positions[map[i]]).norm() * 1000.0;
    sum += d * d;
    mx = std::max(mx, d);
    ++n;
    if (normals) {
      const float c = std::clamp(in.normals[i].normalized().dot(out.normals[map[i]].normalized()), -1.0f, 1.0f);
      angles.push_back(std::acos(c) * 180.0 / M_PI);
    }
  }
  GeomError e{n ? std::sqrt(sum / n) : 0, mx};
  if (!in.colors.empty() && !out.colors.empty()) {
    double se = 0;
    size_t k = 0;
    for (size_t i = 0; i < in.num_vertices(); ++i) {
      if (map[i] == UINT32_MAX) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(in.colors[i][c]) - out.colors[map[i]][c];
        se += d * d;
      }
      k += 3;
    }
    e.color_psnr_db = se == 0 || k == 0 ? 99.0 : std::min(99.0, 10 * std::log10(255.0 * 255.0 / (se / k)));
  }
  if (!angles.empty()) {
    double s = 0;
    for (double a : angles) s += a;
    e.normal_mean_deg = s / angles.size();
    std::sort(angles.begin(), angles.end());
    e.normal_p99_deg = angles[angles.size() * 99 / 100];
    e.normal_max_deg = angles.back();
  }
  return e;
}

// Error to the nearest decoded vertex (for Draco, which renumbers vertices).
GeomError ErrorByNearest(const Mesh& in, const Mesh& out) {
  const float cell = 0.004f;
  auto key = [cell](const Eigen::Vector3f& p, int dx, int dy, int dz) {
    const auto ix = static_cast<int64_t>(std::floor(p.x() / cell)) + dx;
    const auto iy = static_cast<int64_t>(std::floor(p.y() / cell)) + dy;
    const auto iz = static_cast<int64_t>(std::floor(p.z() / cell)) + dz;
    return static_cast<uint64_t>((ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791));
  };
  std::unordered_multimap<uint64_t, uint32_t> grid;
  grid.reserve(out.num_vertices());
  for (size_t i = 0; i < out.num_vertices(); ++i) grid.emplace(key(out.positions[i], 0, 0, 0), static_cast<uint32_t>(i));
  double sum = 0, mx = 0;
  size_t n = 0;
  for (const auto& p : in.positions) {
    float best = 1e9f;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          auto range = grid.equal_range(key(p, dx, dy, dz));
          for (auto it = range.first; it != range.second; ++it) best = std::min(best, (out.positions[it->second] - p).norm());
        }
    const double d = best * 1000.0;
    sum += d * d;
    mx = std::max(mx, d);
    ++n;
  }
  return {n ? std::sqrt(sum / n) : 0, mx};
}

// Two-sided point-to-surface distance between `decoded` and the site's mesh
// `truth`: every vertex of each to the other's surface (TriangleIndex, one
// thread), distances capped at 10 cm. What a viewer sees of the shape,
// whatever the vertices are; G2 moves vertices along their normals only.
struct SurfaceError {
  double rms_mm = 0, max_mm = 0;
};
SurfaceError TwoSidedSurfaceError(const Mesh& decoded, const Mesh& truth) {
  auto a = metrics::TriangleIndex::Build(decoded);
  auto b = metrics::TriangleIndex::Build(truth);
  if (!a.ok() || !b.ok()) return {-1, -1};
  constexpr float kCap = 0.1f;
  double se = 0, mx = 0;
  for (float d : b->DistanceBatch(decoded.positions, kCap, 1)) {
    d = std::min(d, kCap);
    se += double{d} * d;
    mx = std::max<double>(mx, d);
  }
  for (float d : a->DistanceBatch(truth.positions, kCap, 1)) {
    d = std::min(d, kCap);
    se += double{d} * d;
    mx = std::max<double>(mx, d);
  }
  const double n = static_cast<double>(decoded.num_vertices() + truth.num_vertices());
  return {n > 0 ? std::sqrt(se / n) * 1000.0 : 0, mx * 1000.0};
}

// PSNR over foreground pixels (RGB), capped at 99 dB for lossless results.
// 64-bit FNV-1a of n bytes (--hash: blobs and pictures that a speed-up must leave identical).
uint64_t Fnv1a(const uint8_t* p, size_t n) {
  uint64_t h = 1469598103934665603ull;
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

double ForegroundPsnr(const PodImageInput& in, const ImageRgb8& out) {
  double se = 0;
  size_t n = 0;
  for (int y = 0; y < in.color.height(); ++y)
    for (int x = 0; x < in.color.width(); ++x) {
      if (!in.mask.empty() && in.mask.at(x, y) == 0) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(in.color.at(x, y, c)) - out.at(x, y, c);
        se += d * d;
      }
      n += 3;
    }
  if (n == 0 || se == 0) return 99.0;
  return std::min(99.0, 10 * std::log10(255.0 * 255.0 / (se / n)));
}

#if HOLO_BENCH_HAVE_STUDIO
// Runs the capture site in-process on the workload's studio (segmentation
// masks learned from the empty room, the workload's voxel size) for `frames`
// frames and keeps, per frame, the site's fused textured mesh and the pods'
// colour images with the masks the site used. Returns the frames kept, or -1
// (error printed).
int FusedInputs(const Workload& wl, int frames, bool stream_mesh, int stream_step, bool temporal,
                std::vector<FrameInput>* inputs) {
  auto studio = SyntheticStudio::Create(wl.rig, wl.studio);
  StudioOptions empty_options = wl.studio;
  empty_options.empty_room = true;
  auto empty = SyntheticStudio::Create(wl.rig, empty_options);
  if (!studio.ok() || !empty.ok()) {
    spdlog::error("codecs: studio: {} {}", studio.status().ToString(), empty.status().ToString());
    return -1;
  }
  CaptureSiteOptions o;
  o.masks = MaskSource::kSegment;
  o.tsdf.voxel_size = wl.voxel_size_m;
  o.pipeline.max_frames = frames;
  // The live server's default (holoport-server --stream-step 2, the workload's --stream-triangles).
  o.stream_mesh = stream_mesh;
  o.stream_field = stream_mesh;
  o.stream.step = stream_step;
  o.stream.max_triangles = wl.stream_triangles;
  // --content temporal: the site's temporal fusion (docs/temporal.md: the
  // previous volume tracked non-rigidly and fused into), not a fresh volume per frame.
  o.temporal = temporal;
  auto site = CaptureSite::Create(studio->get(), empty->get(), studio->get(), o);
  if (!site.ok()) {
    spdlog::error("codecs: capture site: {}", site.status().ToString());
    return -1;
  }
  int n = 0;
  auto run = (*site)->Run([&](const FrameWork& w) -> Status {
    if (n >= frames) return OkStatus();
    FrameInput& in = (*inputs)[n++];
    in.mesh = w.mesh;
    in.field = w.stream_field;
    in.pods.clear();
    for (const RgbdFrame& f : w.frames.frames) {
      if (f.mask.width() != f.color.width() || f.mask.height() != f.color.height()) {
        return InvalidArgument("pod " + std::to_string(f.pod_id) + ": the site's mask is not the colour image's size");
      }
      in.pods.push_back({f.color, f.mask, {}});
    }
    return OkStatus();
  });
  if (!run.ok()) {
    spdlog::error("codecs: capture site: {}", run.status().ToString());
    return -1;
  }
  inputs->resize(n);
  return n;
}
#endif

struct Figures {
  std::vector<double> bytes, enc, dec, enc_cpu, dec_cpu, a, b;  // a, b: rms/max mm or psnr
  std::vector<double> n_mean, n_p99, n_max;                      // normal angle errors, degrees
  std::vector<double> vcol_psnr;                                 // vertex colour PSNR
  std::vector<double> srms, smax;                                // two-sided surface error, mm
};

int RunCodecs(const BenchArgs& args, const CodecsOptions& co) {
  const std::string& content = co.content;
  // Video runs, checked before any work.
  struct VideoRun {
    std::string label;  // "x264-444"
    protocol::VideoEncodeOptions o;
  };
  std::vector<VideoRun> video_runs;
  {
    const std::string list = co.video;
    size_t at = 0;
    while (at <= list.size()) {
      const size_t comma = std::min(list.find(',', at), list.size());
      std::string label = list.substr(at, comma - at);
      at = comma + 1;
      if (label.empty()) continue;
      // "x264-444@22": this run's CRF (a rate–distortion sweep in one run).
      int crf = co.video_crf;
      if (const size_t amp = label.find('@'); amp != std::string::npos) {
        char* end = nullptr;
        crf = static_cast<int>(std::strtol(label.c_str() + amp + 1, &end, 10));
        if (end == label.c_str() + amp + 1 || *end != '\0') {
          spdlog::error("codecs: --video: bad CRF in '{}'", label);
          return 2;
        }
        label.resize(amp);
      }
      VideoRun r{label, {}};
      if (label == "x264-444" || label == "x264-420") {
        r.o.library = protocol::VideoLibrary::kH264;
      } else if (label == "vpx-vp9-444" || label == "vpx-vp9-420") {
        r.o.library = protocol::VideoLibrary::kVp9;
      } else {
        spdlog::error("codecs: --video: unknown '{}' (x264-444, x264-420, vpx-vp9-444, vpx-vp9-420)", label);
        return 2;
      }
      r.o.chroma_444 = label.size() > 4 && label.substr(label.size() - 3) == "444";
      r.o.crf = crf;
      r.label.append(1, '@').append(std::to_string(crf));
      r.o.preset = co.video_preset;
      r.o.mask_blocks = co.video_mask == "blocks";
      r.o.window = co.video_window == "on";
      r.o.keyframe_interval = co.keyframe_interval.value_or(r.o.keyframe_interval);
      if (const Status st = r.o.Check(); !st.ok()) {
        spdlog::error("codecs: --video {}: {}", label, st.ToString());
        return 2;
      }
      video_runs.push_back(r);
    }
  }
  const bool synthetic = !HOLO_BENCH_HAVE_STUDIO || co.synthetic;
  if (synthetic && (content == "fused" || content == "temporal")) {
    spdlog::error("codecs: --content fused needs the studio (not --synthetic)");
    return 2;
  }
  const int frames = args.frames > 0 ? args.frames : (content == "truth" ? 4 : 60);
  std::string workload = args.workload;
  std::map<std::string, std::string> q0;
  std::vector<FrameInput> inputs(frames);
  if (!synthetic) q0["content"] = content;
  if (synthetic) {
    int w = 640, h = 480;
    if (args.workload == "S8-QVGA") {
      w = 320;
      h = 240;
    } else if (args.workload != "S8-VGA") {
      spdlog::error("codecs: unknown workload '{}' (S8-QVGA or S8-VGA)", args.workload);
      return 2;
    }
    workload = "synthetic-sphere";
    q0["images"] = "8x" + std::to_string(w) + "x" + std::to_string(h);
    q0["mesh"] = "marching-tetrahedra-6mm";
    for (int f = 0; f < frames; ++f) {
      inputs[f].mesh = SyntheticBlob(f, 0.006f);
      for (int p = 0; p < 8; ++p) inputs[f].pods.push_back(SyntheticPodImage(w, h, p, f));
    }
  } else {
#if HOLO_BENCH_HAVE_STUDIO
    auto wl = GetWorkload(args.workload);
    if (!wl.ok()) {
      spdlog::error("codecs: {}", wl.status().ToString());
      return 2;
    }
    if (content == "fused" || content == "temporal") {
      const int got = FusedInputs(*wl, frames, !co.full_mesh, co.stream_step, content == "temporal", &inputs);
      if (got < 0) return 1;
      q0["mesh"] = co.full_mesh ? "site-fused" : "site-stream";
      if (!co.full_mesh) q0["stream_step"] = std::to_string(co.stream_step);
      q0["masks"] = "segment";
    } else {
    SyntheticStudio studio(wl->rig, wl->studio);
    q0["mesh"] = "studio-ground-truth";
    RgbdFrameSet fs;
    StudioGroundTruth gt;
    for (int f = 0; f < frames; ++f) {
      studio.RenderFrame(f, &fs, &gt);
      inputs[f].mesh = gt.foreground_mesh;
      for (size_t p = 0; p < fs.frames.size(); ++p) {
        PodImageInput pi;
        pi.color = fs.frames[p].color;
        pi.depth = fs.frames[p].depth;
        if (p < gt.mask.size() && gt.mask[p].width() == pi.color.width() && gt.mask[p].height() == pi.color.height()) {
          pi.mask = gt.mask[p];
        }
        inputs[f].pods.push_back(std::move(pi));
      }
    }
    }
#endif
  }
  if (inputs.empty()) {
    spdlog::error("codecs: no frames");
    return 1;
  }
  if (!args.json) {
    spdlog::info("codecs: {}, {} frames, mesh {} vertices {} triangles, {} pods", workload, frames,
                 inputs[0].mesh.num_vertices(), inputs[0].mesh.num_triangles(), inputs[0].pods.size());
  }
  q0["vertices"] = std::to_string(inputs[0].mesh.num_vertices());
  q0["triangles"] = std::to_string(inputs[0].mesh.num_triangles());

  auto emit = [&](const std::string& codec, const std::string& metric, double v, const std::string& unit,
                  std::map<std::string, std::string> extra = {}) {
    std::map<std::string, std::string> q = q0;
    q["codec"] = codec;
    for (auto& [k, val] : extra) q[k] = val;
    EmitFigure("codecs", workload, metric, v, unit, q);
  };
  // Median wall and CPU time per frame of one codec's encode and decode.
  auto emit_times = [&](const std::string& codec, const Figures& fig, const std::map<std::string, std::string>& extra) {
    emit(codec, "encode_ms", Median(fig.enc), "ms", extra);
    emit(codec, "decode_ms", Median(fig.dec), "ms", extra);
    emit(codec, "encode_cpu_ms", Median(fig.enc_cpu), "ms", extra);
    emit(codec, "decode_cpu_ms", Median(fig.dec_cpu), "ms", extra);
  };

  std::map<std::string, double> bytes_of, codec_cpu_of, geom_cpu_of;
  // ---- geometry
  struct GeomRun {
    std::string name;
    bool draco;
    protocol::GeometryEncodeOptions g;
    protocol::DracoOptions d;
  };
  std::vector<GeomRun> runs;
  runs.push_back({"G0", false, {}, {}});
  runs.back().g.codec = GeometryCodec::kG0;
  const int chroma_shift = co.chroma_shift.value_or(protocol::GeometryEncodeOptions{}.chroma_shift);
  runs.push_back({"G1", false, {}, {}});
  runs.back().g.chroma_shift = chroma_shift;
  runs.push_back({"G1-normals", false, {}, {}});  // normals sent instead of recomputed
  runs.back().g.normals = protocol::NormalMode::kTransmit;
  runs.back().g.chroma_shift = chroma_shift;
  runs.push_back({"G1-lossless-color", false, {}, {}});  // chroma not quantized
  runs.back().g.chroma_shift = 0;
  runs.push_back({"draco", true, {}, {}});
  runs.push_back({"draco-fast", true, {}, {}});
  runs.back().d.speed = 10;
  // --only=G1,C1 restricts the run to those codecs (for profiling).
  const std::string only = co.only.empty() ? "" : "," + co.only + ",";
  auto wanted = [&](const std::string& name) { return only.empty() || only.find("," + name + ",") != std::string::npos; };
  std::erase_if(runs, [&](const GeomRun& r) { return !wanted(r.name); });
  const bool print_hash = co.hash;
  for (const GeomRun& run : runs) {
    Figures fig;
    // Buffers reused from frame to frame, as a sender and a receiver would.
    std::vector<uint8_t> blob;
    std::vector<uint32_t> map;
    Mesh out;
    for (int rep = 0; rep < args.repeats; ++rep) {
      for (const FrameInput& in : inputs) {
        blob.clear();
        protocol::DracoOptions dopt = run.d;
        if (run.draco) {
          Eigen::Vector3f lo = Eigen::Vector3f::Constant(1e9f), hi = -lo;
          for (const auto& p : in.mesh.positions) {
            lo = lo.cwiseMin(p);
            hi = hi.cwiseMax(p);
          }
          dopt.position_bits = protocol::DracoBitsForStep((hi - lo).maxCoeff(), 0.001f);
        }
        const double c0 = holo::ThreadCpuTimeMs();
        const double t0 = NowMs();
        const Status es = run.draco ? protocol::EncodeDraco(in.mesh, dopt, &blob)
                                    : protocol::EncodeGeometry(in.mesh, run.g, &blob, &map);
        const double t1 = NowMs();
        const double c1 = holo::ThreadCpuTimeMs();
        const Status ds = run.draco ? protocol::DecodeDraco(blob, &out) : protocol::DecodeGeometry(blob, &out);
        const double t2 = NowMs();
        const double c2 = holo::ThreadCpuTimeMs();
        if (!es.ok() || !ds.ok()) {
          spdlog::error("codecs: {} failed: {} {}", run.name, es.ToString(), ds.ToString());
          return 1;
        }
        if (print_hash && rep == 0) {  // to check that a speed-up leaves the bytes identical
          const uint64_t hsh = Fnv1a(blob.data(), blob.size());
          // Raw lines (no log prefix) that two runs' outputs can be diffed on.
          std::fprintf(stderr, "HASH %s %zu %016llx\n", run.name.c_str(), blob.size(), static_cast<unsigned long long>(hsh));
        }
        fig.bytes.push_back(static_cast<double>(blob.size()));
        fig.enc.push_back(t1 - t0);
        fig.dec.push_back(t2 - t1);
        fig.enc_cpu.push_back(c1 - c0);
        fig.dec_cpu.push_back(c2 - c1);
        if (rep == 0) {
          const GeomError e = run.draco ? ErrorByNearest(in.mesh, out) : ErrorByMap(in.mesh, out, map);
          fig.a.push_back(e.rms_mm);
          fig.b.push_back(e.max_mm);
          if (e.color_psnr_db >= 0) fig.vcol_psnr.push_back(e.color_psnr_db);
          if (run.name == "G1") {  // the measure G2 is held to, for the comparison
            const SurfaceError se = TwoSidedSurfaceError(out, in.mesh);
            fig.srms.push_back(se.rms_mm);
            fig.smax.push_back(se.max_mm);
          }
          if (e.normal_mean_deg >= 0) {
            fig.n_mean.push_back(e.normal_mean_deg);
            fig.n_p99.push_back(e.normal_p99_deg);
            fig.n_max.push_back(e.normal_max_deg);
          }
        }
      }
    }
    std::map<std::string, std::string> extra;
    if (run.draco) {
      extra["peer"] = "draco";
      extra["error"] = "nearest-vertex";
      extra["draco_speed"] = std::to_string(run.d.speed);
    }
    const double bytes = Median(fig.bytes);
    bytes_of[run.name] = bytes;
    emit(run.name, "bytes_per_frame", bytes, "B", extra);
    emit(run.name, "mbps", bytes * 8 * 30 / 1e6, "Mbit/s", extra);
    emit_times(run.name, fig, extra);
    geom_cpu_of[run.name] = Median(fig.enc_cpu) + Median(fig.dec_cpu);
    emit(run.name, "geom_rms_mm", Median(fig.a), "mm", extra);
    emit(run.name, "geom_max_mm", *std::max_element(fig.b.begin(), fig.b.end()), "mm", extra);
    if (!fig.vcol_psnr.empty()) emit(run.name, "vertex_color_psnr_db", Median(fig.vcol_psnr), "dB", extra);
    if (!fig.srms.empty()) {
      extra["error"] = "two-sided-surface";
      emit(run.name, "geom_surface_rms_mm", Mean(fig.srms), "mm", extra);
      emit(run.name, "geom_surface_max_mm", *std::max_element(fig.smax.begin(), fig.smax.end()), "mm", extra);
      extra.erase("error");
    }
    if (!fig.n_mean.empty()) {  // vs the input's normals; G1 recomputes them from the decoded triangles
      emit(run.name, "normal_mean_deg", Median(fig.n_mean), "deg", extra);
      emit(run.name, "normal_p99_deg", Median(fig.n_p99), "deg", extra);
      emit(run.name, "normal_max_deg", *std::max_element(fig.n_max.begin(), fig.n_max.end()), "deg", extra);
    }
  }
  // ---- G2 (temporal): one encoder and one decoder over the frame sequence
  // (fresh ones per repeat). Bytes are the mean over the sequence, keyframes
  // included; the error is the two-sided surface distance between the
  // decoded mesh and the site's mesh of the same frame.
  if (wanted("G2")) {
    protocol::Geometry2EncodeOptions o;
    o.keyframe.chroma_shift = chroma_shift;
    if (co.g2_step_mm) o.displacement_step_m = *co.g2_step_mm / 1000.0f;
    if (co.g2_max_rms_mm) o.max_rms_m = *co.g2_max_rms_mm / 1000.0f;
    if (co.g2_keyframe_step_mm) o.keyframe.position_step_m = *co.g2_keyframe_step_mm / 1000.0f;
    if (co.g2_dead_zone) o.dead_zone_steps = *co.g2_dead_zone;
    if (co.g2_group) o.max_group_frames = *co.g2_group;
    if (co.g2_smooth) o.smooth_passes = *co.g2_smooth;
    if (co.g2_no_backoff) o.backoff = false;
    if (co.g2_far_fraction) o.max_far_fraction = *co.g2_far_fraction;
    if (co.g2_max_disp_mm) o.max_displacement_m = *co.g2_max_disp_mm / 1000.0f;
    if (const Status st = o.Check(); !st.ok()) {
      spdlog::error("codecs: G2 options: {}", st.ToString());
      return 2;
    }
    if (!args.json) {  // how much the site's mesh itself changes from frame to frame
      for (size_t f = 1; f < inputs.size() && f < 6; ++f) {
        const SurfaceError se = TwoSidedSurfaceError(inputs[f - 1].mesh, inputs[f].mesh);
        spdlog::info("G2: site mesh frame {} vs {}: two-sided rms {:.3f} mm, max {:.1f} mm", f - 1, f, se.rms_mm, se.max_mm);
      }
    }
    Figures fig;
    std::vector<double> key_bytes, pred_bytes, key_enc_cpu, pred_enc_cpu, key_dec_cpu, pred_dec_cpu;
    std::map<std::string, int> reasons;
    std::vector<uint8_t> blob;
    Mesh out;
    for (int rep = 0; rep < args.repeats; ++rep) {
      protocol::Geometry2Encoder enc(o);
      protocol::Geometry2Decoder dec;
      for (const FrameInput& in : inputs) {
        blob.clear();
        protocol::Geometry2FrameInfo info;
        const double c0 = holo::ThreadCpuTimeMs();
        const double t0 = NowMs();
        const Status es = enc.Encode(in.mesh, &blob, &info);
        const double t1 = NowMs();
        const double c1 = holo::ThreadCpuTimeMs();
        const Status ds = es.ok() ? dec.Decode(blob, &out) : es;
        const double t2 = NowMs();
        const double c2 = holo::ThreadCpuTimeMs();
        if (!ds.ok()) {
          spdlog::error("codecs: G2 failed: {}", ds.ToString());
          return 1;
        }
        fig.enc.push_back(t1 - t0);
        fig.dec.push_back(t2 - t1);
        fig.enc_cpu.push_back(c1 - c0);
        fig.dec_cpu.push_back(c2 - c1);
        (info.keyframe ? key_enc_cpu : pred_enc_cpu).push_back(c1 - c0);
        (info.keyframe ? key_dec_cpu : pred_dec_cpu).push_back(c2 - c1);
        if (rep == 0) {
          fig.bytes.push_back(static_cast<double>(blob.size()));
          (info.keyframe ? key_bytes : pred_bytes).push_back(static_cast<double>(blob.size()));
          if (info.keyframe) ++reasons[info.reason];
          const SurfaceError se = TwoSidedSurfaceError(out, in.mesh);
          fig.a.push_back(se.rms_mm);
          fig.b.push_back(se.max_mm);
          if (!args.json) {
            spdlog::info("G2 frame {}: {} {} B, rms {:.3f} mm, max {:.1f} mm; checked rms {:.3f} mm far {:.4f} "
                         "flipped {:.4f}{}",
                         fig.bytes.size() - 1, info.keyframe ? "key" : "pred", blob.size(), se.rms_mm, se.max_mm,
                         info.rms_m * 1000, info.far_fraction, info.flipped_fraction,
                         info.keyframe ? " (" + info.reason + ")" : "");
          }
        }
      }
    }
    std::map<std::string, std::string> extra{{"frames", std::to_string(inputs.size())},
                                             {"error", "two-sided-surface"},
                                             {"max_group_frames", std::to_string(o.max_group_frames)},
                                             {"displacement_step_mm", Fixed(o.displacement_step_m * 1000, 2)},
                                             {"keyframe_step_mm", Fixed(o.keyframe.position_step_m * 1000, 2)},
                                             {"max_rms_mm", Fixed(o.max_rms_m * 1000, 2)},
                                             {"max_far_fraction", Fixed(o.max_far_fraction, 3)}};
    const double bytes = Mean(fig.bytes);
    bytes_of["G2"] = bytes;
    emit("G2", "bytes_per_frame", bytes, "B", extra);
    emit("G2", "mbps", bytes * 8 * 30 / 1e6, "Mbit/s", extra);
    emit("G2", "keyframe_ratio", static_cast<double>(key_bytes.size()) / static_cast<double>(fig.bytes.size()), "1",
         extra);
    if (!key_bytes.empty()) emit("G2", "keyframe_bytes", Mean(key_bytes), "B", extra);
    if (!pred_bytes.empty()) emit("G2", "predicted_bytes", Mean(pred_bytes), "B", extra);
    for (const auto& [reason, n] : reasons) {
      auto e = extra;
      e["reason"] = reason;
      emit("G2", "keyframes", n, "1", e);
    }
    emit_times("G2", fig, extra);
    emit("G2", "encode_cpu_ms_mean", Mean(fig.enc_cpu), "ms", extra);
    emit("G2", "decode_cpu_ms_mean", Mean(fig.dec_cpu), "ms", extra);
    if (!pred_enc_cpu.empty()) {
      emit("G2", "predicted_encode_cpu_ms", Median(pred_enc_cpu), "ms", extra);
      emit("G2", "predicted_decode_cpu_ms", Median(pred_dec_cpu), "ms", extra);
    }
    if (!key_enc_cpu.empty()) {
      emit("G2", "keyframe_encode_cpu_ms", Median(key_enc_cpu), "ms", extra);
      emit("G2", "keyframe_decode_cpu_ms", Median(key_dec_cpu), "ms", extra);
    }
    geom_cpu_of["G2"] = Mean(fig.enc_cpu) + Mean(fig.dec_cpu);
    emit("G2", "geom_rms_mm", Mean(fig.a), "mm", extra);
    emit("G2", "geom_rms_mm_worst_frame", *std::max_element(fig.a.begin(), fig.a.end()), "mm", extra);
    emit("G2", "geom_max_mm", *std::max_element(fig.b.begin(), fig.b.end()), "mm", extra);
    emit("G2", "geom_surface_rms_mm", Mean(fig.a), "mm", extra);
    if (bytes_of.count("G1")) emit("G2", "bytes_ratio_vs_G1", bytes / bytes_of["G1"], "1", {{"peer", "G1"}});
  }
  // ---- G3: the stream mesh's grid (fused and temporal content, stream mesh).
  if (wanted("G3") && !inputs.empty() && inputs[0].field.size() > 0) {
    protocol::SurfaceEncodeOptions o;
    if (co.g3_step_mm) o.position_step_m = *co.g3_step_mm / 1000.0f;
    if (const Status st = o.Check(); !st.ok()) {
      spdlog::error("codecs: G3 options: {}", st.ToString());
      return 2;
    }
    Figures fig;
    std::vector<double> tris, label_b, value_b, brick_b, samples;
    std::vector<uint8_t> blob;
    Mesh out;
    for (int rep = 0; rep < args.repeats; ++rep) {
      for (const FrameInput& in : inputs) {
        blob.clear();
        protocol::SurfaceEncodeStats st;
        const double c0 = holo::ThreadCpuTimeMs();
        const double t0 = NowMs();
        const Status es = protocol::EncodeSurface(in.field, o, &blob, nullptr, &st);
        const double t1 = NowMs();
        const double c1 = holo::ThreadCpuTimeMs();
        const Status ds = es.ok() ? protocol::DecodeGeometry(blob, &out) : es;
        const double t2 = NowMs();
        const double c2 = holo::ThreadCpuTimeMs();
        if (!es.ok() || !ds.ok()) {
          spdlog::error("codecs: G3 failed: {} {}", es.ToString(), ds.ToString());
          return 1;
        }
        fig.bytes.push_back(static_cast<double>(blob.size()));
        fig.enc.push_back(t1 - t0);
        fig.dec.push_back(t2 - t1);
        fig.enc_cpu.push_back(c1 - c0);
        fig.dec_cpu.push_back(c2 - c1);
        if (rep == 0) {
          const SurfaceError se = TwoSidedSurfaceError(out, in.mesh);
          fig.a.push_back(se.rms_mm);
          fig.b.push_back(se.max_mm);
          tris.push_back(static_cast<double>(out.num_triangles()));
          brick_b.push_back(static_cast<double>(st.brick_bytes));
          label_b.push_back(static_cast<double>(st.label_bytes));
          value_b.push_back(static_cast<double>(st.crossing_bytes));
          samples.push_back(static_cast<double>(st.grid_samples));
        }
      }
    }
    std::map<std::string, std::string> extra{{"error", "two-sided-surface"},
                                             {"g3_step_mm", Fixed(o.position_step_m * 1000.0f, 2)}};
    const double bytes = Median(fig.bytes);
    bytes_of["G3"] = bytes;
    emit("G3", "bytes_per_frame", bytes, "B", extra);
    emit("G3", "mbps", bytes * 8 * 30 / 1e6, "Mbit/s", extra);
    emit("G3", "brick_bytes", Median(brick_b), "B", extra);
    emit("G3", "label_bytes", Median(label_b), "B", extra);
    emit("G3", "crossing_bytes", Median(value_b), "B", extra);
    emit_times("G3", fig, extra);
    geom_cpu_of["G3"] = Median(fig.enc_cpu) + Median(fig.dec_cpu);
    emit("G3", "geom_surface_rms_mm", Mean(fig.a), "mm", extra);
    emit("G3", "geom_rms_mm", Mean(fig.a), "mm", extra);
    emit("G3", "geom_max_mm", *std::max_element(fig.b.begin(), fig.b.end()), "mm", extra);
    emit("G3", "triangles", Median(tris), "1", extra);
    emit("G3", "grid_samples", Median(samples), "1", extra);
    if (bytes_of.count("G1")) emit("G3", "bytes_ratio_vs_G1", bytes / bytes_of["G1"], "1", {{"peer", "G1"}});
    if (inputs.size() >= 2) {
      // Each grid labelled once, kept for the next pair.
      GridRepeat all;
      LabelledGrid before, now;
      for (size_t k = 0; k < inputs.size(); ++k) {
        std::swap(before, now);
        now.grid = &inputs[k].field;
        SurfaceLabels(*now.grid, &now.labels, &now.codes);
        if (k > 0) all += FrameToFrame(before, now);
      }
      const std::map<std::string, std::string> between{{"between", "consecutive frames, same world samples"}};
      auto frac = [](size_t a, size_t b) { return b ? static_cast<double>(a) / static_cast<double>(b) : 0.0; };
      emit("G3", "repeat_label_fraction", frac(all.same_label, all.labelled), "1", between);
      emit("G3", "repeat_case_fraction", frac(all.same_case, all.cubes), "1", between);
      emit("G3", "repeat_crossing_fraction", frac(all.edges_alike, all.edges), "1", between);
      if (!all.shift_mm.empty()) {
        auto with = [&](const char* stat) { auto m = between; m["stat"] = stat; return m; };
        emit("G3", "crossing_shift_mm", InterpolatedQuantile(all.shift_mm, 0.5), "mm", with("p50"));
        emit("G3", "crossing_shift_mm", InterpolatedQuantile(all.shift_mm, 0.9), "mm", with("p90"));
        const double step_mm = o.position_step_m * 1000.0;
        size_t within = 0;
        for (double v : all.shift_mm) within += v < step_mm;
        auto m = between;
        m["step_mm"] = Fixed(static_cast<float>(step_mm), 2);
        emit("G3", "crossing_within_step_fraction", frac(within, all.edges), "1", m);
      }
    }
  }
  for (const GeomRun& run : runs) {
    // Where G1's bytes go: its u32-length streams after the 29 bytes of prefix and G1 header
    // (flags: bit 0 normals sent, bit 1 colours).
    if (run.draco || run.g.codec != GeometryCodec::kG1) continue;
    std::vector<uint8_t> blob;
    if (!protocol::EncodeGeometry(inputs[0].mesh, run.g, &blob).ok() || blob.size() < 29) continue;
    std::vector<const char*> streams{"connectivity", "positions"};
    if (blob[1] & 1) streams.push_back("normals");
    if (blob[1] & 2) streams.push_back("colors");
    size_t off = 29;
    for (const char* stream : streams) {
      if (off + 4 > blob.size()) break;
      uint32_t n = 0;
      std::memcpy(&n, blob.data() + off, 4);
      emit(run.name, "stream_bytes", n, "B", {{"stream", stream}});
      if (std::string(stream) == "connectivity") {
        emit(run.name, "connectivity_bits_per_triangle", n * 8.0 / std::max<size_t>(1, inputs[0].mesh.num_triangles()),
             "bit");
      }
      off += 4 + n;
    }
  }
  if (!inputs[0].mesh.normals.empty()) {
    // The share of G1's normal error that is the method rather than the
    // quantization: area-weighted normals of the unquantized input vs its own normals.
    Mesh m = inputs[0].mesh;
    protocol::RecomputeNormals(&m);
    std::vector<uint32_t> identity(m.num_vertices());
    for (size_t i = 0; i < identity.size(); ++i) identity[i] = static_cast<uint32_t>(i);
    const GeomError e = ErrorByMap(inputs[0].mesh, m, identity);
    emit("area-weighted-unquantized", "normal_mean_deg", e.normal_mean_deg, "deg");
    emit("area-weighted-unquantized", "normal_p99_deg", e.normal_p99_deg, "deg");
    emit("area-weighted-unquantized", "normal_max_deg", e.normal_max_deg, "deg");
  }
  if (bytes_of.count("G0")) emit("G1", "bytes_ratio_vs_G0", bytes_of["G1"] / bytes_of["G0"], "1");
  if (bytes_of.count("draco")) emit("draco", "bytes_ratio_vs_G1", bytes_of["draco"] / bytes_of["G1"], "1", {{"peer", "draco"}});

  // ---- colour
  for (ColorCodec codec : {ColorCodec::kC0, ColorCodec::kC1}) {
    const std::string name = codec == ColorCodec::kC0 ? "C0" : "C1";
    if (!wanted(name)) continue;
    protocol::ColorEncodeOptions o;
    o.codec = codec;
    o.jpeg_quality = co.jpeg_quality.value_or(o.jpeg_quality);
    if (co.chroma444) o.chroma_420 = false;
    if (co.chroma420) o.chroma_420 = true;
    if (co.fill_mean) o.fill = protocol::ColorEncodeOptions::Fill::kMean;
    if (co.fill_pad) o.fill = protocol::ColorEncodeOptions::Fill::kPad;
    if (co.fill_push_pull) o.fill = protocol::ColorEncodeOptions::Fill::kPushPull;
    if (co.fast_dct) o.accurate_dct = false;
    if (co.quant_standard) o.quant = protocol::ColorEncodeOptions::Quant::kStandard;
    if (co.no_optimize_huffman) o.optimize_huffman = false;
    if (co.no_pack) o.pack_blocks = false;
    o.mask_zstd_level = co.mask_zstd_level.value_or(o.mask_zstd_level);
    o.huffman_refresh = co.huffman_refresh.value_or(o.huffman_refresh);
    Figures fig;
    // As a sender and a receiver would: per pod one encoder, one blob buffer
    // and one decoder (which keeps its images), reused from frame to frame.
    const size_t npods = inputs.empty() ? 0 : inputs[0].pods.size();
    std::vector<std::vector<uint8_t>> blobs(npods);
    std::vector<protocol::ColorDecoder> decoders(npods);
    std::vector<protocol::ColorEncoder> encoders(npods, protocol::ColorEncoder(o));
    for (int rep = 0; rep < args.repeats; ++rep) {
      for (const FrameInput& in : inputs) {
        double bytes = 0, enc = 0, dec = 0, enc_cpu = 0, dec_cpu = 0, psnr = 0;
        for (size_t p = 0; p < in.pods.size() && p < npods; ++p) {
          const PodImageInput& pod = in.pods[p];
          std::vector<uint8_t>& blob = blobs[p];
          blob.clear();
          const double c0 = holo::ThreadCpuTimeMs();
          const double t0 = NowMs();
          const Status es = encoders[p].Encode(pod.color, pod.mask, &blob);
          const double t1 = NowMs();
          const double c1 = holo::ThreadCpuTimeMs();
          const Status ds = decoders[p].Decode(blob);
          const double t2 = NowMs();
          const double c2 = holo::ThreadCpuTimeMs();
          enc_cpu += c1 - c0;
          dec_cpu += c2 - c1;
          if (!es.ok() || !ds.ok()) {
            spdlog::error("codecs: {} failed: {} {}", name, es.ToString(), ds.ToString());
            return 1;
          }
          bytes += static_cast<double>(blob.size());
          enc += t1 - t0;
          dec += t2 - t1;
          if (rep == 0) psnr += ForegroundPsnr(pod, decoders[p].image()) / static_cast<double>(in.pods.size());
        }
        fig.bytes.push_back(bytes);
        fig.enc.push_back(enc);
        fig.dec.push_back(dec);
        fig.enc_cpu.push_back(enc_cpu);
        fig.dec_cpu.push_back(dec_cpu);
        if (rep == 0) fig.a.push_back(psnr);
      }
    }
    const double bytes = Median(fig.bytes);
    bytes_of[name] = bytes;
    std::map<std::string, std::string> extra{{"pods", std::to_string(inputs[0].pods.size())}};
    if (codec == ColorCodec::kC1) {
      extra["jpeg_quality"] = std::to_string(o.jpeg_quality);
      extra["chroma"] = o.chroma_420 ? "420" : "444";
      extra["layout"] = o.pack_blocks ? "packed" : "box";
      extra["fill"] = o.fill == protocol::ColorEncodeOptions::Fill::kPad        ? "pad"
                      : o.fill == protocol::ColorEncodeOptions::Fill::kPushPull ? "push-pull"
                                                                                : "mean";
      extra["huffman_refresh"] = std::to_string(o.huffman_refresh);
    }
    emit(name, "bytes_per_frame", bytes, "B", extra);
    emit(name, "mbps", bytes * 8 * 30 / 1e6, "Mbit/s", extra);
    emit_times(name, fig, extra);
    emit(name, "codec_cpu_ms", Median(fig.enc_cpu) + Median(fig.dec_cpu), "ms", extra);
    codec_cpu_of[name] = Median(fig.enc_cpu) + Median(fig.dec_cpu);
    // The mean includes the frames whose Huffman tables were optimized (one in huffman_refresh per pod).
    emit(name, "encode_cpu_ms_mean", Mean(fig.enc_cpu), "ms", extra);
    emit(name, "color_psnr_db", Median(fig.a), "dB", extra);
  }

  // ---- depth (D1, D2): every pod's depth image as holoport-pod sends it (the
  // studio's noisy pod depth with dropouts; truth content only), one encoder
  // and decoder buffer reused throughout. Figures per pod frame; the pod's
  // whole stream adds its colour as holoport-pod sends it (C1, JPEG quality
  // 60, whole image, no mask) and the PodFrame message around both.
  const bool have_depth = !inputs.empty() && !inputs[0].pods.empty() && !inputs[0].pods[0].depth.empty();
  std::map<std::string, double> depth_bytes_of, depth_cpu_of;
  double pod_color_bytes = 0, pod_message_overhead = 0;
  if (have_depth && (wanted("D1") || wanted("D2"))) {
    protocol::ColorEncodeOptions o;
    o.jpeg_quality = 60;  // holoport-pod's default (server/pods/pod_runner.h)
    protocol::ColorEncoder enc(o);
    std::vector<double> sizes;
    std::vector<uint8_t> blob;
    for (const FrameInput& in : inputs)
      for (const PodImageInput& pod : in.pods) {
        blob.clear();
        if (!enc.Encode(pod.color, ImageGray8(), &blob).ok()) {
          spdlog::error("codecs: pod colour failed");
          return 1;
        }
        sizes.push_back(static_cast<double>(blob.size()));
      }
    pod_color_bytes = Mean(sizes);
    // The PodFrame message minus its two blobs (header, ids, times, codec bytes, lengths).
    protocol::PodFrame pf;
    pf.depth.assign(1, 0);
    pf.color.assign(1, 0);
    pod_message_overhead = static_cast<double>(protocol::EncodeMessage({}, pf).size()) - 2;
    const std::map<std::string, std::string> extra{{"jpeg_quality", "60"}, {"mask", "none"}};
    emit("C1-pod", "bytes_per_pod_frame", pod_color_bytes, "B", extra);
  }
  for (const protocol::DepthCodec dc : {protocol::DepthCodec::kD1, protocol::DepthCodec::kD2}) {
    const std::string name = dc == protocol::DepthCodec::kD1 ? "D1" : "D2";
    if (!have_depth || !wanted(name)) continue;
    protocol::DepthEncodeOptions o;
    o.codec = dc;
    Figures fig;
    std::vector<uint8_t> blob;
    ImageDepth16 out;
    size_t invalid = 0, pixels = 0;
    for (int rep = 0; rep < args.repeats; ++rep) {
      for (const FrameInput& in : inputs) {
        for (const PodImageInput& pod : in.pods) {
          blob.clear();
          const double c0 = holo::ThreadCpuTimeMs();
          const double t0 = NowMs();
          const Status es = protocol::EncodeDepth(pod.depth, o, &blob);
          const double t1 = NowMs();
          const double c1 = holo::ThreadCpuTimeMs();
          const Status ds = es.ok() ? protocol::DecodeDepth(blob, &out) : es;
          const double t2 = NowMs();
          const double c2 = holo::ThreadCpuTimeMs();
          if (!ds.ok()) {
            spdlog::error("codecs: {} failed: {}", name, ds.ToString());
            return 1;
          }
          if (rep == 0) {
            if (out != pod.depth) {
              spdlog::error("codecs: {} is not lossless", name);
              return 1;
            }
            fig.bytes.push_back(static_cast<double>(blob.size()));
            for (int y = 0; y < pod.depth.height(); ++y)
              for (int x = 0; x < pod.depth.width(); ++x) invalid += pod.depth.at(x, y) == 0;
            pixels += pod.depth.num_pixels();
          }
          fig.enc.push_back(t1 - t0);
          fig.dec.push_back(t2 - t1);
          fig.enc_cpu.push_back(c1 - c0);
          fig.dec_cpu.push_back(c2 - c1);
        }
      }
    }
    const double bytes = Mean(fig.bytes);
    depth_bytes_of[name] = bytes;
    depth_cpu_of[name] = Median(fig.enc_cpu) + Median(fig.dec_cpu);
    std::map<std::string, std::string> extra{{"content", "studio-pod-depth"},
                                             {"pod_frames", std::to_string(fig.bytes.size())},
                                             {"invalid_fraction", std::to_string(static_cast<double>(invalid) /
                                                                                 static_cast<double>(std::max<size_t>(1, pixels)))}};
    if (dc == protocol::DepthCodec::kD1) extra["zstd_level"] = std::to_string(o.zstd_level);
    if (dc == protocol::DepthCodec::kD2) extra["noise_at_1m_um"] = std::to_string(o.noise_at_1m_um);
    emit(name, "bytes_per_pod_frame", bytes, "B", extra);
    emit(name, "bits_per_pixel", bytes * 8 / static_cast<double>(inputs[0].pods[0].depth.num_pixels()), "bit", extra);
    emit(name, "depth_mbps_per_pod", bytes * 8 * 30 / 1e6, "Mbit/s", extra);
    emit_times(name, fig, extra);
    emit(name, "codec_cpu_ms", depth_cpu_of[name], "ms", extra);
    if (pod_color_bytes > 0) {
      extra["color"] = "C1-q60-no-mask";
      emit(name, "pod_mbps", (bytes + pod_color_bytes + pod_message_overhead) * 8 * 30 / 1e6, "Mbit/s", extra);
    }
  }
  if (depth_bytes_of.count("D1") && depth_bytes_of.count("D2")) {
    const std::map<std::string, std::string> extra{{"content", "studio-pod-depth"}, {"peer", "D1"}};
    emit("D2", "bytes_ratio_vs_D1", depth_bytes_of["D2"] / depth_bytes_of["D1"], "1", extra);
    emit("D2", "codec_cpu_ratio_vs_D1", depth_cpu_of["D2"] / depth_cpu_of["D1"], "1", extra);
  }

  // ---- video colour (V1): one encoder and one decoder per pod over the sequence
  std::map<std::string, double> video_bytes_of, video_cpu_of;
  for (const VideoRun& run : (wanted("video") ? video_runs : std::vector<VideoRun>{})) {
    Figures fig;
    std::vector<double> key_bytes, delta_bytes, mask_bytes, window_fraction;
    double window_resizes = 0;
    const size_t npods = inputs.empty() ? 0 : inputs[0].pods.size();
    for (int rep = 0; rep < args.repeats; ++rep) {
      std::vector<std::unique_ptr<protocol::VideoEncoder>> encoders;
      std::vector<std::unique_ptr<protocol::VideoDecoder>> decoders;
      for (size_t p = 0; p < npods; ++p) {
        auto e = protocol::VideoEncoder::Create(run.o);
        if (!e.ok()) {
          spdlog::error("codecs: video {}: {}", run.label, e.status().ToString());
          return 1;
        }
        encoders.push_back(std::move(*e));
        decoders.push_back(std::make_unique<protocol::VideoDecoder>());
      }
      std::vector<uint8_t> blob;
      for (const FrameInput& in : inputs) {
        double bytes = 0, enc = 0, dec = 0, enc_cpu = 0, dec_cpu = 0, psnr = 0;
        for (size_t p = 0; p < in.pods.size() && p < npods; ++p) {
          const PodImageInput& pod = in.pods[p];
          blob.clear();
          const double c0 = holo::ThreadCpuTimeMs();
          const double t0 = NowMs();
          const Status es = encoders[p]->Encode(pod.color, pod.mask, &blob);
          const double t1 = NowMs();
          const double c1 = holo::ThreadCpuTimeMs();
          const Status ds = es.ok() ? decoders[p]->Decode(blob) : es;
          const double t2 = NowMs();
          const double c2 = holo::ThreadCpuTimeMs();
          if (!es.ok() || !ds.ok()) {
            spdlog::error("codecs: video {} failed: {}", run.label, ds.ToString());
            return 1;
          }
          bytes += static_cast<double>(blob.size());
          enc += t1 - t0;
          dec += t2 - t1;
          enc_cpu += c1 - c0;
          dec_cpu += c2 - c1;
          if (print_hash && rep == 0) {  // the blob and the decoded picture: a speed-up must leave both identical
            const uint64_t hb = Fnv1a(blob.data(), blob.size());
            const ImageRgb8& im = decoders[p]->image();
            const uint64_t hi = Fnv1a(im.data(), im.num_pixels() * 3);
            std::fprintf(stderr, "HASH %s pod %zu %zu %016llx %016llx\n", run.label.c_str(), p, blob.size(),
                         static_cast<unsigned long long>(hb), static_cast<unsigned long long>(hi));
          }
          if (rep == 0) {
            psnr += ForegroundPsnr(pod, decoders[p]->image()) / static_cast<double>(in.pods.size());
            auto info = protocol::ParseVideoBlob(blob);
            if (info.ok()) {
              (info->keyframe() ? key_bytes : delta_bytes).push_back(static_cast<double>(blob.size()));
              mask_bytes.push_back(static_cast<double>(info->mask_bytes));
              window_fraction.push_back(double(info->window.w) * info->window.h /
                                        (double(info->width) * info->height));
            }
          }
        }
        fig.bytes.push_back(bytes);
        fig.enc.push_back(enc);
        fig.dec.push_back(dec);
        fig.enc_cpu.push_back(enc_cpu);
        fig.dec_cpu.push_back(dec_cpu);
        if (rep == 0) fig.a.push_back(psnr);
      }
      if (rep == 0) {
        for (const auto& e : encoders) window_resizes += static_cast<double>(e->window_resizes());
      }
    }
    const protocol::VideoEncodeOptions& o = run.o;
    std::map<std::string, std::string> extra{
        {"window", o.window ? "on" : "off"},
        {"pods", std::to_string(npods)},
        {"library", protocol::VideoLibraryName(o.library)},
        {"chroma", o.chroma_444 ? "444" : "420"},
        {"crf", std::to_string(o.crf)},
        {"preset", o.preset.empty() ? "default" : o.preset},
        {"mask", o.mask_blocks ? "blocks" : "rows"},
        {"keyframe_interval", std::to_string(o.keyframe_interval)},
        {"frames", std::to_string(inputs.size())}};
    const double bytes = Mean(fig.bytes);  // keyframes included
    video_bytes_of[run.label] = bytes;
    emit("video", "bytes_per_frame", bytes, "B", extra);
    emit("video", "mbps", bytes * 8 * 30 / 1e6, "Mbit/s", extra);
    emit("video", "keyframe_bytes_per_pod", Mean(key_bytes), "B", extra);
    emit("video", "delta_bytes_per_pod", Mean(delta_bytes), "B", extra);
    emit("video", "mask_bytes_per_pod", Mean(mask_bytes), "B", extra);
    emit("video", "picture_area_fraction", Mean(window_fraction), "1", extra);
    emit("video", "window_resizes", window_resizes, "1", extra);
    emit_times("video", fig, extra);
    emit("video", "encode_cpu_ms_mean", Mean(fig.enc_cpu), "ms", extra);
    emit("video", "decode_cpu_ms_mean", Mean(fig.dec_cpu), "ms", extra);
    video_cpu_of[run.label] = Mean(fig.enc_cpu) + Mean(fig.dec_cpu);
    emit("video", "codec_cpu_ms", video_cpu_of[run.label], "ms", extra);
    emit("video", "color_psnr_db", Mean(fig.a), "dB", extra);
  }

  // ---- peer for C1's time: plain TurboJPEG (4:4:4, standard tables, accurate
  // DCT) of each pod's foreground bounding box as it is, encoded and decoded
  // into buffers kept between frames — the least work a JPEG-of-the-box
  // codec does. Its time prices the same machine's JPEG speed in this run.
  if (wanted("C1") || wanted("jpeg-box")) {
    const int quality = co.peer_jpeg_quality;
    tjhandle enc_h = tjInitCompress(), dec_h = tjInitDecompress();
    if (enc_h == nullptr || dec_h == nullptr) {
      spdlog::error("codecs: TurboJPEG handles: {}", tjGetErrorStr2(nullptr));
      return 1;
    }
    Figures fig;
    std::vector<unsigned char> jpeg, pixels;
    for (int rep = 0; rep < args.repeats; ++rep) {
      for (const FrameInput& in : inputs) {
        double bytes = 0, enc_cpu = 0, dec_cpu = 0, psnr_sum = 0;
        for (const PodImageInput& pod : in.pods) {
          const int W = pod.color.width(), H = pod.color.height();
          int x0 = W, y0 = H, x1 = -1, y1 = -1;
          for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x)
              if (pod.mask.empty() || pod.mask.at(x, y)) {
                x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
              }
          if (x1 < 0) continue;
          const int bw = x1 - x0 + 1, bh = y1 - y0 + 1;
          jpeg.resize(tjBufSize(bw, bh, TJSAMP_444));
          pixels.resize(static_cast<size_t>(bw) * bh * 3);
          unsigned char* dst = jpeg.data();
          unsigned long size = jpeg.size();
          const double c0 = holo::ThreadCpuTimeMs();
          const int e = tjCompress2(enc_h, &pod.color.at(x0, y0), bw, W * 3, bh, TJPF_RGB, &dst, &size, TJSAMP_444,
                                    quality, TJFLAG_ACCURATEDCT | TJFLAG_NOREALLOC);
          const double c1 = holo::ThreadCpuTimeMs();
          const int d = e != 0 ? -1
                               : tjDecompress2(dec_h, jpeg.data(), size, pixels.data(), bw, bw * 3, bh, TJPF_RGB,
                                               TJFLAG_ACCURATEDCT);
          const double c2 = holo::ThreadCpuTimeMs();
          if (e != 0 || d != 0) {
            spdlog::error("codecs: jpeg-box peer failed: {}", tjGetErrorStr2(e != 0 ? enc_h : dec_h));
            return 1;
          }
          bytes += static_cast<double>(size);
          enc_cpu += c1 - c0;
          dec_cpu += c2 - c1;
          if (rep == 0) {
            double se = 0;
            size_t n = 0;
            for (int y = 0; y < bh; ++y)
              for (int x = 0; x < bw; ++x) {
                if (!pod.mask.empty() && !pod.mask.at(x0 + x, y0 + y)) continue;
                for (int c = 0; c < 3; ++c) {
                  const double diff = static_cast<double>(pod.color.at(x0 + x, y0 + y, c)) - pixels[(static_cast<size_t>(y) * bw + x) * 3 + c];
                  se += diff * diff;
                }
                n += 3;
              }
            psnr_sum += se == 0 ? 99.0 : std::min(99.0, 10 * std::log10(255.0 * 255.0 / (se / n)));
          }
        }
        fig.bytes.push_back(bytes);
        fig.enc_cpu.push_back(enc_cpu);
        fig.dec_cpu.push_back(dec_cpu);
        if (rep == 0) fig.a.push_back(psnr_sum / static_cast<double>(std::max<size_t>(1, in.pods.size())));
      }
    }
    tjDestroy(enc_h);
    tjDestroy(dec_h);
    const std::map<std::string, std::string> extra{{"peer", "turbojpeg"}, {"jpeg_quality", std::to_string(quality)},
                                                   {"chroma", "444"}};
    const double peer_ms = Median(fig.enc_cpu) + Median(fig.dec_cpu);
    emit("jpeg-box", "bytes_per_frame", Median(fig.bytes), "B", extra);
    emit("jpeg-box", "encode_cpu_ms", Median(fig.enc_cpu), "ms", extra);
    emit("jpeg-box", "decode_cpu_ms", Median(fig.dec_cpu), "ms", extra);
    emit("jpeg-box", "codec_cpu_ms", peer_ms, "ms", extra);
    emit("jpeg-box", "color_psnr_db", Median(fig.a), "dB", extra);
    if (codec_cpu_of.count("C1") && peer_ms > 0)
      emit("C1", "codec_cpu_ratio_vs_jpeg_box", codec_cpu_of["C1"] / peer_ms, "1", {{"peer", "turbojpeg"}});
  }
  if (bytes_of.count("G0") && bytes_of.count("C0"))
    emit("G0+C0", "stream_mbps", (bytes_of["G0"] + bytes_of["C0"]) * 8 * 30 / 1e6, "Mbit/s");
  if (bytes_of.count("G1") && bytes_of.count("C1"))
    emit("G1+C1", "stream_mbps", (bytes_of["G1"] + bytes_of["C1"]) * 8 * 30 / 1e6, "Mbit/s");
  if (bytes_of.count("G3") && bytes_of.count("C1"))
    emit("G3+C1", "stream_mbps", (bytes_of["G3"] + bytes_of["C1"]) * 8 * 30 / 1e6, "Mbit/s");
  if (codec_cpu_of.count("C1") && geom_cpu_of.count("G1"))
    emit("G1+C1", "codec_cpu_ms", geom_cpu_of["G1"] + codec_cpu_of["C1"], "ms");
  for (const VideoRun& run : video_runs) {
    if (!video_bytes_of.count(run.label) || !bytes_of.count("G1")) continue;
    const std::map<std::string, std::string> extra{{"library", protocol::VideoLibraryName(run.o.library)},
                                                   {"chroma", run.o.chroma_444 ? "444" : "420"},
                                                   {"crf", std::to_string(run.o.crf)}};
    emit("G1+video", "stream_mbps", (bytes_of["G1"] + video_bytes_of[run.label]) * 8 * 30 / 1e6, "Mbit/s", extra);
    if (geom_cpu_of.count("G1"))
      emit("G1+video", "codec_cpu_ms", geom_cpu_of["G1"] + video_cpu_of[run.label], "ms", extra);
  }
  return 0;
}

}  // namespace

BenchFn SetupCodecs(CLI::App& app) {
  auto co = std::make_shared<CodecsOptions>();
  app.add_option("--content", co->content,
                 "truth (the studio's ground truth), fused (the capture site's output) or temporal (the site with "
                 "temporal fusion)")
      ->check(CLI::IsMember({"truth", "fused", "temporal"}))
      ->capture_default_str();
  app.add_flag("--full-mesh", co->full_mesh,
               "fused: the site's full-resolution mesh instead of the stream mesh (20 k triangles) the live server sends");
  app.add_option("--stream-step", co->stream_step,
                 "fused: the stream mesh's grid step in voxels, 2..4 (holoport-server --stream-step)")
      ->check(CLI::Range(2, 4))
      ->capture_default_str();
  app.add_flag("--synthetic", co->synthetic, "workload synthetic-sphere (a noisy blob) instead of the studio");
  app.add_option("--only", co->only, "only these codecs, comma-separated (e.g. G1,C1)");
  app.add_flag("--hash", co->hash,
               "print a hash of every geometry blob, and of every V1 blob and its decoded picture, of the first "
               "repeat to stderr");
  app.add_option("--chroma-shift", co->chroma_shift, "G1 vertex colour quantization shift");
  app.add_option("--jpeg-quality", co->jpeg_quality, "C1 JPEG quality 1..100")->check(CLI::Range(1, 100));
  app.add_flag("--chroma444", co->chroma444, "C1 4:4:4 chroma");
  app.add_flag("--chroma420", co->chroma420, "C1 4:2:0 chroma (wins over --chroma444)");
  app.add_flag("--fill-pad", co->fill_pad, "C1 background fill: pad");
  app.add_flag("--fill-push-pull", co->fill_push_pull, "C1 background fill: push-pull");
  app.add_flag("--fill-mean", co->fill_mean, "C1 background fill: mean");
  app.add_flag("--fast-dct", co->fast_dct, "C1 fast integer DCT instead of the accurate one");
  app.add_flag("--quant-standard", co->quant_standard, "C1 standard JPEG quantization tables");
  app.add_flag("--no-optimize-huffman", co->no_optimize_huffman, "C1 standard Huffman tables");
  app.add_flag("--no-pack", co->no_pack, "C1 pod images in their boxes, not packed blocks");
  app.add_option("--mask-zstd-level", co->mask_zstd_level, "C1 mask rows' zstd level");
  app.add_option("--huffman-refresh", co->huffman_refresh, "C1 Huffman table refresh interval, frames");
  app.add_option("--peer-jpeg-quality", co->peer_jpeg_quality, "the jpeg-box peer's TurboJPEG quality")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app.add_option("--video", co->video,
                 "V1 runs, comma-separated LIBRARY-CHROMA[@CRF]: x264-444, x264-420, vpx-vp9-444, vpx-vp9-420, ...")
      ->capture_default_str();
  app.add_option("--video-crf", co->video_crf, "V1 CRF for runs without @CRF (-1: the encoder's default)")
      ->capture_default_str();
  app.add_option("--video-preset", co->video_preset, "V1 encoder preset (default: the library's)");
  app.add_option("--video-mask", co->video_mask, "V1 mask format: blocks (coded 16x16 blocks) or rows (zstd rows)")
      ->capture_default_str()
      ->check(CLI::IsMember({"blocks", "rows"}));
  app.add_option("--video-window", co->video_window,
                 "V1 picture: on = a window around the foreground, off = the whole pod image")
      ->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option("--keyframe-interval", co->keyframe_interval, "V1 frames between key frames");
  app.add_option("--g2-step-mm", co->g2_step_mm, "G2 displacement step, mm");
  app.add_option("--g2-max-rms-mm", co->g2_max_rms_mm, "G2 keyframe when the two-sided RMS would exceed this, mm");
  app.add_option("--g2-keyframe-step-mm", co->g2_keyframe_step_mm, "G2 keyframes' G1 position step, mm");
  app.add_option("--g2-dead-zone", co->g2_dead_zone, "G2 residual dead zone, steps (0.5 = plain rounding)");
  app.add_option("--g2-group", co->g2_group, "G2 longest group of frames (keyframe included)");
  app.add_option("--g2-far-fraction", co->g2_far_fraction,
                 "G2 keyframe when more than this share of the error samples is farther than 1 cm");
  app.add_flag("--g2-no-backoff", co->g2_no_backoff, "G2 tries a predicted frame every frame (no back-off)");
  app.add_option("--g2-smooth", co->g2_smooth, "G2 one-ring smoothing passes of the target displacements");
  app.add_option("--g2-max-disp-mm", co->g2_max_disp_mm, "G2 farthest surface search along a normal, mm");
  app.add_option("--g3-step-mm", co->g3_step_mm, "G3 quantization of a vertex along its grid edge, mm (default 2)");
  return [co](const BenchArgs& args) { return RunCodecs(args, *co); };
}

HOLO_REGISTER_BENCH_OPTIONS(
    "codecs",
    "geometry (G0, G1, Draco) and colour (C0, C1, V1 video) codecs on truth or fused content: bytes, time, error",
    SetupCodecs);

}  // namespace holo::bench
