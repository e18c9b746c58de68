// holoport-bench client: figures of the viewer client, one part per topic.
//   render  render_ms at 1280×720 on whatever GL the headless context gets
//           (llvmpipe here), per-vertex colour and projective texturing,
//           plus the per-stream-frame costs (upload, pod visibility maps) and
//           the novel-view PSNR of both modes against the studio's truth.
// Adding a part (pose prediction, reprojection): write a function
//   int RunClientXxxPart(const holo::bench::BenchArgs& args, const std::vector<std::string>& options);
// (in this file or in bench_client_xxx.cc, declared below) and add it to kParts with the
// options it takes. `--parts render,xxx` runs a subset; by default all run.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "bench.h"
#include "client/render/gl_context.h"
#include "client/render/renderer.h"
#include "client/render/view.h"
#include "common/clock.h"
#include "common/metrics/image_metrics.h"
#include "common/pose.h"
#include "server/studio/studio.h"
#include "server/studio/workloads.h"
#include "server/texture/texturer.h"

namespace {

using holo::bench::EmitFigure;
using holo::bench::Median;
using holo::bench::ProcessCpuMs;

// Value of `--name V` in `options`, or `fallback`.
std::string OptionValue(const std::vector<std::string>& options, const std::string& name, const std::string& fallback) {
  for (size_t i = 0; i + 1 < options.size(); ++i) {
    if (options[i] == name) return options[i + 1];
  }
  return fallback;
}

// Midpoint subdivision (every triangle into four, shared edge midpoints):
// the same surface with 4^levels times the triangles, to time the renderer
// at the density of a fused mesh.
holo::Mesh Subdivide(const holo::Mesh& in, int levels) {
  holo::Mesh m = in;
  for (int l = 0; l < levels; ++l) {
    holo::Mesh out;
    out.positions = m.positions;
    out.normals = m.normals;
    out.colors = m.colors;
    std::unordered_map<uint64_t, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      const uint64_t key = (static_cast<uint64_t>(std::min(a, b)) << 32) | std::max(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      const uint32_t idx = static_cast<uint32_t>(out.positions.size());
      out.positions.push_back(0.5f * (m.positions[a] + m.positions[b]));
      if (!m.normals.empty()) out.normals.push_back((m.normals[a] + m.normals[b]).normalized());
      if (!m.colors.empty()) {
        std::array<uint8_t, 3> c;
        for (int k = 0; k < 3; ++k) c[k] = static_cast<uint8_t>((m.colors[a][k] + m.colors[b][k] + 1) / 2);
        out.colors.push_back(c);
      }
      mid.emplace(key, idx);
      return idx;
    };
    for (const auto& t : m.triangles) {
      const uint32_t ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
      out.triangles.push_back({t[0], ab, ca});
      out.triangles.push_back({ab, t[1], bc});
      out.triangles.push_back({ca, bc, t[2]});
      out.triangles.push_back({ab, bc, ca});
    }
    m = std::move(out);
  }
  return m;
}

holo::CameraModel OrbitCamera(int width, int height, float azimuth_deg, float radius) {
  const float a = azimuth_deg * static_cast<float>(M_PI) / 180.0f;
  holo::CameraModel c;
  c.intrinsics = holo::Intrinsics::FromFov(width, height, 60.0);
  c.world_from_camera =
      holo::LookAt(Eigen::Vector3f(radius * std::cos(a), radius * std::sin(a), 1.6f), Eigen::Vector3f(0, 0, 1.0f));
  return c;
}

int RunClientRenderPart(const holo::bench::BenchArgs& args, const std::vector<std::string>& options) {
  const int width = std::atoi(OptionValue(options, "--width", "1280").c_str());
  const int height = std::atoi(OptionValue(options, "--height", "720").c_str());
  std::vector<int> levels;
  {
    std::stringstream ss(OptionValue(options, "--subdivide", "0,2"));
    std::string item;
    while (std::getline(ss, item, ',')) levels.push_back(std::atoi(item.c_str()));
  }
  if (width < 16 || height < 16 || width > 8192 || height > 8192) {
    std::fprintf(stderr, "client: --width/--height must be in 16..8192\n");
    return 2;
  }
  for (int l : levels) {
    if (l < 0 || l > 4) {
      std::fprintf(stderr, "client: --subdivide levels must be in 0..4\n");
      return 2;
    }
  }
  const int frames = args.frames > 0 ? args.frames : 60;
  const int64_t studio_frame = 40;

  auto workload = holo::GetWorkload(args.workload);
  if (!workload.ok()) {
    std::fprintf(stderr, "client: %s\n", workload.status().ToString().c_str());
    return 2;
  }
  holo::StudioOptions so = workload->studio;
  so.color_variation = false;  // a server calibrates its pods
  so.threads = 2;
  auto studio = holo::SyntheticStudio::Create(workload->rig, so);
  if (!studio.ok()) {
    std::fprintf(stderr, "client: %s\n", studio.status().ToString().c_str());
    return 1;
  }
  holo::RgbdFrameSet frames_set;
  holo::StudioGroundTruth gt;
  (*studio)->RenderFrame(studio_frame, &frames_set, &gt);
  // What the stream carries: the mesh with the server texturer's colours and the pods' images.
  holo::Mesh mesh = gt.foreground_mesh;
  mesh.colors.clear();
  holo::TextureOptions to;
  to.threads = 2;
  holo::Texturer texturer(workload->rig, to);
  if (holo::Status s = texturer.Apply(frames_set, &mesh); !s.ok()) {
    std::fprintf(stderr, "client: %s\n", s.ToString().c_str());
    return 1;
  }
  std::vector<const holo::ImageRgb8*> images;
  for (const auto& f : frames_set.frames) images.push_back(&f.color);

  auto ctx = holo::render::CreateHeadlessContext();
  if (!ctx.ok()) {
    std::fprintf(stderr, "client: %s\n", ctx.status().ToString().c_str());
    return 1;
  }
  auto renderer = holo::render::Renderer::Create();
  auto target = holo::render::OffscreenTarget::Create(width, height);
  if (!renderer.ok() || !target.ok()) {
    std::fprintf(stderr, "client: %s\n",
                 (!renderer.ok() ? renderer.status() : target.status()).ToString().c_str());
    return 1;
  }
  const std::string gl_renderer = holo::render::CurrentGlRenderer();
  const char* lp_threads = std::getenv("LP_NUM_THREADS");
  const std::string res = std::to_string(width) + "x" + std::to_string(height);
  if (!args.json) std::fprintf(stderr, "client render: %s, %s, %d frames per mode\n", gl_renderer.c_str(), res.c_str(), frames);

  // Novel-view PSNR of both modes against the truth (exact geometry, 4 views
  // between the pods at 640×480, inside the true foreground).
  {
    auto small = holo::render::OffscreenTarget::Create(640, 480);
    if (!small.ok()) return 1;
    for (auto mode : {holo::render::ColorMode::kVertexColor, holo::render::ColorMode::kProjective}) {
      if (!(*renderer)->SetRemoteMesh(mesh).ok() || !(*renderer)->SetPodImages(workload->rig, images).ok()) return 1;
      std::vector<double> psnr;
      for (float az : {22.5f, 112.5f, 202.5f, 292.5f}) {
        const holo::CameraModel cam = OrbitCamera(640, 480, az, 2.0f);
        holo::ImageRgb8 truth, ours;
        holo::ImageGray8 mask;
        (*studio)->RenderView(studio_frame, cam, &truth, nullptr, &mask);
        (*small)->Bind();
        holo::render::RenderSettings settings;
        settings.mode = mode;
        settings.background = {0, 0, 0};
        if (holo::Status s = (*renderer)->Render(cam, settings, {0, 0, 640, 480}); !s.ok()) {
          std::fprintf(stderr, "client: %s\n", s.ToString().c_str());
          return 1;
        }
        if (!(*small)->ReadRgb(&ours).ok()) return 1;
        auto p = holo::metrics::ComputePsnr(ours, truth, &mask);
        if (!p.ok()) return 1;
        psnr.push_back(*p);
      }
      EmitFigure("client", args.workload, "novel_view_psnr_db", holo::bench::Mean(psnr), "dB",
                 {{"mode", holo::render::ColorModeName(mode)}, {"stage", "render"}, {"resolution", "640x480"},
                  {"views", "4"}, {"frame", std::to_string(studio_frame)}});
    }
  }

  for (int level : levels) {
    const holo::Mesh m = Subdivide(mesh, level);
    const std::string tris = std::to_string(m.num_triangles());
    // Per-stream-frame costs: upload of mesh + pod images, pod visibility maps.
    std::vector<double> upload_ms, vis_ms, vis_cpu;
    for (int r = 0; r < 7; ++r) {
      holo::Stopwatch sw;
      if (!(*renderer)->SetRemoteMesh(m).ok() || !(*renderer)->SetPodImages(workload->rig, images).ok()) return 1;
      holo::render::FinishGl();
      upload_ms.push_back(sw.ElapsedMs());
      sw.Restart();
      const double cpu0 = ProcessCpuMs();
      if (!(*renderer)->UpdateVisibility().ok()) return 1;
      holo::render::FinishGl();
      vis_ms.push_back(sw.ElapsedMs());
      vis_cpu.push_back(ProcessCpuMs() - cpu0);
    }
    std::map<std::string, std::string> q = {{"stage", "render"}, {"triangles", tris}, {"resolution", res},
                                            {"renderer", gl_renderer}, {"pods", std::to_string(images.size())}};
    if (lp_threads) q["lp_num_threads"] = lp_threads;
    EmitFigure("client", args.workload, "upload_ms", Median(upload_ms), "ms", q);
    EmitFigure("client", args.workload, "visibility_ms", Median(vis_ms), "ms", q);
    EmitFigure("client", args.workload, "visibility_cpu_ms", Median(vis_cpu), "ms", q);
    for (auto mode : {holo::render::ColorMode::kVertexColor, holo::render::ColorMode::kProjective}) {
      holo::render::RenderSettings settings;
      settings.mode = mode;
      (*target)->Bind();
      std::vector<double> ms, cpu;
      for (int i = -5; i < frames; ++i) {  // 5 warm-up frames
        const holo::CameraModel cam = OrbitCamera(width, height, 3.0f * static_cast<float>(i), 2.5f);
        const double cpu0 = ProcessCpuMs();
        holo::Stopwatch sw;
        if (holo::Status s = (*renderer)->Render(cam, settings, {0, 0, width, height}); !s.ok()) {
          std::fprintf(stderr, "client: %s\n", s.ToString().c_str());
          return 1;
        }
        holo::render::FinishGl();
        if (i >= 0) {
          ms.push_back(sw.ElapsedMs());
          cpu.push_back(ProcessCpuMs() - cpu0);
        }
      }
      auto qm = q;
      qm["mode"] = holo::render::ColorModeName(mode);
      qm["frames"] = std::to_string(frames);
      EmitFigure("client", args.workload, "render_ms", Median(ms), "ms", qm);
      EmitFigure("client", args.workload, "render_cpu_ms", Median(cpu), "ms", qm);
    }
  }
  return 0;
}

struct Part {
  const char* name;
  std::vector<std::string> options;  // options with a value this part reads
  int (*run)(const holo::bench::BenchArgs&, const std::vector<std::string>&);
};

const std::vector<Part>& Parts() {
  static const std::vector<Part> parts = {
      {"render", {"--width", "--height", "--subdivide"}, RunClientRenderPart},
  };
  return parts;
}

int RunClientBench(const holo::bench::BenchArgs& args) {
  std::set<std::string> selected;
  std::set<std::string> known = {"--parts"};
  for (const Part& p : Parts()) known.insert(p.options.begin(), p.options.end());
  for (size_t i = 0; i < args.extra.size(); i += 2) {
    if (!known.count(args.extra[i]) || i + 1 >= args.extra.size()) {
      std::fprintf(stderr, "client: unknown option or missing value: %s\n", args.extra[i].c_str());
      return 2;
    }
  }
  {
    std::stringstream ss(OptionValue(args.extra, "--parts", ""));
    std::string item;
    while (std::getline(ss, item, ',')) selected.insert(item);
  }
  for (const std::string& s : selected) {
    if (std::none_of(Parts().begin(), Parts().end(), [&](const Part& p) { return s == p.name; })) {
      std::fprintf(stderr, "client: unknown part '%s'\n", s.c_str());
      return 2;
    }
  }
  for (const Part& p : Parts()) {
    if (!selected.empty() && !selected.count(p.name)) continue;
    if (int rc = p.run(args, args.extra); rc != 0) return rc;
  }
  return 0;
}

}  // namespace

HOLO_REGISTER_BENCH("client", "viewer: render_ms at 1280x720 (per-vertex colour, projective texturing), novel-view PSNR",
                    RunClientBench);
