// holoport-bench client: figures of the viewer client, one part per topic.
//   render  render_ms at 1280×720 on whatever GL the headless context gets
//           (llvmpipe here), per-vertex colour and projective texturing,
//           plus the per-stream-frame costs (upload, pod visibility maps) and
//           the novel-view PSNR of both modes against the studio's truth;
//           per mesh (fused: the site's full mesh, its stream mesh, and the
//           stream mesh as G3 gives it to a viewer) the per-new-mesh CPU
//           and the share of the pods' foreground pixels the texturing reads
//           (used_pixel_share).
//   stream  what the live stream's codecs cost that PSNR, per quality layer
//           (viewer_psnr_loss_db, stream_mbps).
// Adding a part: write a function
//   int RunClientXxxPart(const holo::bench::BenchArgs& args, const ClientBenchOptions& options);
// add its options to ClientBenchOptions and SetupClient, and the part to Parts().
// `--parts render,xxx` runs a subset; by default all run. (Pose prediction and
// reprojection are benchmarks of their own: client-pose, client-offload.)
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

#include <CLI/CLI.hpp>

#include "bench.h"
#include "client/render/gl_context.h"
#include "client/render/renderer.h"
#include "client/render/view.h"
#include "common/clock.h"
#include "common/file_util.h"
#include "common/image_io.h"
#include "common/log.h"
#include "common/metrics/triangle_index.h"
#include "common/metrics/image_metrics.h"
#include "common/pose.h"
#include "protocol/byte_io.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/surface_codec.h"
#include "protocol/video_codec.h"
#include "server/net/site_publisher.h"
#include "server/pipeline/capture_site.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "texture/mesh_renderer.h"
#include "texture/texturer.h"

namespace {

using holo::bench::EmitFigure;
using holo::bench::Median;
using holo::bench::ProcessCpuMs;

// The benchmark's own options (holoport-bench client --help).
struct ClientBenchOptions {
  std::string parts;                             // "render,...": a subset of the parts ("": all)
  std::string resolutions = "960x540,1280x720";  // WxH[,WxH...]
  std::string content = "fused";                 // fused | truth
  std::string png_dir;                           // write the novel views as PNGs here
  std::string legacy = "0";                      // 1: RenderSettings::Legacy(), no mask-edge texturing
  int64_t frame = 40;                            // studio frame of the content
  size_t reduce = 0;                             // triangle budget of the site's stream mesh (fused; 0: the workload's)
  int stream_step = holo::StreamMeshOptions{}.step;  // the stream mesh's grid step (fused; holoport-server --stream-step)
  std::string cull = "1";                        // 0: no back-face culling
  std::string prepass;                           // 0 | 1: depth pre-pass (default: the renderer's)
  int pods_per_vertex = -1;                      // ProjectiveOptions::pods_per_vertex (-1: the renderer's)
  float visibility_mm = -1;                      // ProjectiveOptions::visibility_tolerance_m, mm (-1: the renderer's)
  int max_pods_per_triangle = -1;                // ProjectiveOptions::max_pods_per_triangle (-1: the renderer's)
  std::string gpu_visibility;                    // 0 | 1: ProjectiveOptions::gpu_visibility (default: the renderer's)
  float behind_band = -1;                        // the site's TsdfOptions::behind_band (fused; -1: the default)
  float behind_sigmas = -1;                      // the site's TsdfOptions::behind_noise_sigmas (fused; -1: the default)
  int bake_texels = -1;                          // ProjectiveOptions::bake_texels_per_edge (-1: the renderer's)
  float bake_density = -1;                       // ProjectiveOptions::bake_texels_per_pod_pixel (-1: the renderer's)
  double reduced_step_scale = -1;                // stream part: the reduced layer's (-1: SitePublisher's default)
  double g3_step_mm = -1;                        // stream part: G3's position step (-1: SitePublisher's default)
  int reduced_jpeg_quality = -1;                 // stream part: the reduced layer's (-1: SitePublisher's default)
  int video_frames = 30;                         // stream part, fused: frames of V1 video before the measured one (0: no V1)
  std::string video_crfs = "24,30";              // stream part: the full layer's V1 CRFs to measure
  std::string video_preset;                      // stream part: V1's encoder preset ("": SitePublisher's)
  std::string video_chroma;                      // stream part: V1's chroma, 444 or 420 ("": SitePublisher's)
};

holo::CameraModel OrbitCamera(int width, int height, float azimuth_deg, float radius) {
  const float a = azimuth_deg * static_cast<float>(M_PI) / 180.0f;
  holo::CameraModel c;
  c.intrinsics = holo::Intrinsics::FromFov(width, height, 60.0);
  c.world_from_camera =
      holo::LookAt(Eigen::Vector3f(radius * std::cos(a), radius * std::sin(a), 1.6f), Eigen::Vector3f(0, 0, 1.0f));
  return c;
}

// What a viewer receives for one frame: the mesh with the site's per-vertex
// colours, and the pods' colour images with their masks.
struct ViewerContent {
  std::string content;  // "truth" | "fused"
  std::string mesh_name;  // "truth", "fused_full", "fused_stream"
  holo::Mesh mesh;
  // Fused: p10, p50, p90 of the vertices' signed distance to the true
  // surface (mm, positive outside; within 5 cm of it). Empty for the truth.
  std::vector<double> signed_mm;
  std::vector<holo::ImageRgb8> images;
  std::vector<holo::ImageGray8> masks;  // empty = none (whole images)
  // Fused: the pods' images and masks as the site has them, before the
  // colour codec (the reference of the stream part).
  std::vector<holo::ImageRgb8> raw_images;
  std::vector<holo::ImageGray8> raw_masks;
  // Fused, stream part: the same for the frames before it, oldest first
  // (sequence[k][pod]; the last is the measured frame), for the V1 video
  // codec, which needs the frames a live encoder would have seen.
  std::vector<std::vector<holo::ImageRgb8>> sequence_images;
  std::vector<std::vector<holo::ImageGray8>> sequence_masks;
  // Fused stream mesh: the grid it was extracted from (the G3 codec's input).
  holo::SdfGrid field;
  std::vector<const holo::ImageRgb8*> ImagePtrs() const {
    std::vector<const holo::ImageRgb8*> v;
    for (const auto& i : images) v.push_back(&i);
    return v;
  }
  std::vector<const holo::ImageGray8*> MaskPtrs() const {
    std::vector<const holo::ImageGray8*> v;
    for (const auto& m : masks) v.push_back(&m);
    return v;
  }
};

// Ground truth as the viewer has measured it so far: the studio's exact
// mesh coloured by the site's texturer, and the pods' whole colour images.
holo::Status MakeTruthContent(const holo::Workload& workload, holo::SyntheticStudio* studio, int64_t frame,
                              ViewerContent* out) {
  holo::RgbdFrameSet fs;
  holo::StudioGroundTruth gt;
  studio->RenderFrame(frame, &fs, &gt);
  out->content = "truth";
  out->mesh_name = "truth";
  out->mesh = gt.foreground_mesh;
  out->mesh.colors.clear();
  holo::TextureOptions to;
  to.threads = 2;
  holo::Texturer texturer(workload.rig, to);
  HOLO_RETURN_IF_ERROR(texturer.Apply(fs, &out->mesh));
  for (auto& f : fs.frames) out->images.push_back(std::move(f.color));
  return holo::OkStatus();
}

// The live fused stream: the real capture site (segmentation with a learned
// background, TSDF fusion, marching cubes + clean-up, texturer) run
// in-process on the studio's frames 0..`frame`; the frame's full-resolution
// mesh and its pods' colour images through the C1 colour codec with the
// site's masks, exactly as a viewer decodes them (background pixels 0).
// Also, in `reduced`, the site's stream mesh of that frame (StreamMesher,
// budget `reduced_triangles`: what holoport-server --listen publishes),
// both re-textured by the site's texturer.
holo::Status MakeFusedContent(const holo::Workload& workload, int64_t frame, size_t reduced_triangles, int stream_step,
                              const holo::TextureOptions& texture_options, float behind_band, float behind_sigmas,
                              int sequence_frames, bool temporal,
                              ViewerContent* full, ViewerContent* reduced) {
  holo::StudioOptions so = workload.studio;
  HOLO_ASSIGN_OR_RETURN(auto studio, holo::SyntheticStudio::Create(workload.rig, so));
  so.empty_room = true;
  HOLO_ASSIGN_OR_RETURN(auto empty, holo::SyntheticStudio::Create(workload.rig, so));
  holo::CaptureSiteOptions o;
  o.masks = holo::MaskSource::kSegment;
  o.tsdf.voxel_size = workload.voxel_size_m;
  if (behind_band > 0) o.tsdf.behind_band = behind_band;
  if (behind_sigmas >= 0) o.tsdf.behind_noise_sigmas = behind_sigmas;
  o.pipeline.serial = true;
  o.pipeline.max_frames = frame + 1;
  o.temporal = temporal;  // holoport-server --temporal: tracked, temporally fused
  // What holoport-server --listen publishes: the compact stream mesh; the
  // full-resolution mesh beside it.
  o.stream_mesh = true;
  o.stream.max_triangles = reduced_triangles > 0 ? reduced_triangles : workload.stream_triangles;
  o.stream.step = stream_step;
  o.stream_field = true;
  o.full_mesh = true;
  HOLO_ASSIGN_OR_RETURN(auto site, holo::CaptureSite::Create(studio.get(), empty.get(), nullptr, o));
  holo::RgbdFrameSet kept;
  holo::Mesh stream_mesh;
  holo::SdfGrid stream_field;
  std::vector<std::vector<holo::ImageRgb8>> sequence_images;
  std::vector<std::vector<holo::ImageGray8>> sequence_masks;
  bool got = false;
  auto stats = site->Run([&](const holo::FrameWork& w) {
    if (w.frames.frame_index > frame - sequence_frames && w.frames.frame_index <= frame) {
      sequence_images.emplace_back();
      sequence_masks.emplace_back();
      for (const auto& f : w.frames.frames) {
        sequence_images.back().push_back(f.color);
        sequence_masks.back().push_back(f.mask);
      }
    }
    if (w.frames.frame_index == frame) {
      full->mesh = w.full_mesh;
      stream_mesh = w.mesh;
      stream_field = w.stream_field;
      kept = w.frames;
      got = true;
    }
    return holo::OkStatus();
  });
  HOLO_RETURN_IF_ERROR(stats.status());
  if (!got) return holo::Internal("the capture site did not deliver frame " + std::to_string(frame));
  full->content = temporal ? "temporal" : "fused";
  full->mesh_name = "fused_full";
  for (const auto& f : kept.frames) {
    full->raw_images.push_back(f.color);
    full->raw_masks.push_back(f.mask);
    std::vector<uint8_t> blob;
    HOLO_RETURN_IF_ERROR(holo::protocol::EncodeColor(f.color, f.mask, {}, &blob));
    holo::ImageRgb8 img;
    holo::ImageGray8 mask;
    HOLO_RETURN_IF_ERROR(holo::protocol::DecodeColor(blob, &img, &mask));
    full->images.push_back(std::move(img));
    full->masks.push_back(std::move(mask));
  }
  *reduced = *full;
  // The sequence goes with the stream mesh only (the stream part's).
  reduced->sequence_images = std::move(sequence_images);
  reduced->sequence_masks = std::move(sequence_masks);
  reduced->mesh_name = "fused_stream";
  reduced->mesh = std::move(stream_mesh);
  reduced->field = std::move(stream_field);
  // Both meshes coloured by the texturer with `texture_options` (the site's
  // defaults unless a before/after comparison asks otherwise).
  holo::TextureOptions to = texture_options;
  to.threads = 2;
  holo::Texturer texturer(workload.rig, to);
  for (holo::Mesh* m : {&full->mesh, &reduced->mesh}) {
    m->colors.clear();
    HOLO_RETURN_IF_ERROR(texturer.Apply(kept, m));
  }
  // Signed distance of every vertex to the true surface (positive outside):
  // a fused surface that sits inside or outside the person shows here.
  holo::RgbdFrameSet truth_frames;
  holo::StudioGroundTruth gt;
  studio->RenderFrame(frame, &truth_frames, &gt);
  HOLO_ASSIGN_OR_RETURN(auto index, holo::metrics::TriangleIndex::Build(gt.foreground_mesh));
  const auto& tp = gt.foreground_mesh.positions;
  for (ViewerContent* c : {full, reduced}) {
    std::vector<double> sd;
    for (const auto& p : c->mesh.positions) {
      const auto q = index.Query(p, 0.05f);
      if (!q.found()) continue;
      const auto& t = gt.foreground_mesh.triangles[q.triangle];
      const Eigen::Vector3f n = (tp[t[1]] - tp[t[0]]).cross(tp[t[2]] - tp[t[0]]);
      sd.push_back(1000.0 * ((p - q.point).dot(n) >= 0 ? q.distance : -q.distance));
    }
    if (sd.empty()) continue;
    std::sort(sd.begin(), sd.end());
    c->signed_mm = {sd[sd.size() / 10], sd[sd.size() / 2], sd[sd.size() * 9 / 10]};
  }
  return holo::OkStatus();
}

// Novel-view quality of one content and mode: 4 views between the pods at
// 640×480 (radius 2 m), PSNR and SSIM against the studio's ground-truth
// render of the same frame, inside the true foreground ("region":"truth")
// and inside the union of the true and the rendered foreground
// ("region":"union": fringes and floaters count too); and inside their
// intersection ("region":"overlap": the colour where the geometry covers the
// person, without the pixels it misses), with the fraction of the true
// foreground the render covers (`novel_view_coverage`).
struct Quality {
  double psnr = 0, ssim = 0, psnr_union = 0, psnr_overlap = 0, coverage = 0;
};
// The share of the pods' foreground (mask) pixels the viewer's texturing
// reads: a pixel counts when the front-most triangle there (the mesh
// rasterized in that pod's colour camera) is textured from that pod
// (`triangle_pods`, the renderer's selection), or when such a pixel is its
// neighbour (bilinear fetches). Issue 18's question: how many of the pixels
// a colour codec sends does the picture use?
double UsedPixelShare(const holo::Rig& rig, const holo::Mesh& mesh, const std::vector<uint16_t>& triangle_pods,
                      const std::vector<holo::ImageGray8>& masks) {
  if (triangle_pods.size() != mesh.num_triangles() || masks.size() != rig.pods.size()) return -1;
  size_t used = 0, foreground = 0;
  holo::MeshRasterizer raster;
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    const holo::ImageGray8& mask = masks[i];
    if (mask.empty()) return -1;
    raster.Rasterize(mesh.positions, mesh.triangles, rig.pods[i].ColorCamera(), /*want_attributes=*/true);
    const std::vector<int32_t>& id = raster.triangle_ids();
    const int w = mask.width(), h = mask.height();
    if (raster.width() != w || raster.height() != h) return -1;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        if (mask.row(y)[x] < 128) continue;
        ++foreground;
        bool hit = false;
        for (int yy = std::max(0, y - 1); yy <= std::min(h - 1, y + 1) && !hit; ++yy) {
          for (int xx = std::max(0, x - 1); xx <= std::min(w - 1, x + 1) && !hit; ++xx) {
            const int32_t t = id[static_cast<size_t>(yy) * w + xx];
            hit = t >= 0 && (triangle_pods[static_cast<size_t>(t)] >> i & 1u);
          }
        }
        used += hit ? 1 : 0;
      }
    }
  }
  return foreground > 0 ? static_cast<double>(used) / static_cast<double>(foreground) : -1;
}

holo::Status MeasureQuality(holo::render::Renderer* renderer, holo::render::OffscreenTarget* target,
                            holo::SyntheticStudio* studio, int64_t frame, const holo::render::RenderSettings& base,
                            Quality* q) {
  std::vector<double> psnr, ssim, psnr_union, psnr_overlap, coverage;
  for (float az : {22.5f, 112.5f, 202.5f, 292.5f}) {
    const holo::CameraModel cam = OrbitCamera(target->width(), target->height(), az, 2.0f);
    holo::ImageRgb8 truth, ours;
    holo::ImageGray8 mask;
    studio->RenderView(frame, cam, &truth, nullptr, &mask);
    target->Bind();
    holo::render::RenderSettings settings = base;
    settings.background = {0, 0, 0};
    HOLO_RETURN_IF_ERROR(renderer->Render(cam, settings, {0, 0, target->width(), target->height()}));
    HOLO_RETURN_IF_ERROR(target->ReadRgb(&ours));
    HOLO_ASSIGN_OR_RETURN(double p, holo::metrics::ComputePsnr(ours, truth, &mask));
    HOLO_ASSIGN_OR_RETURN(double s, holo::metrics::ComputeSsim(ours, truth, &mask));
    holo::ImageGray8 uni = mask, both = mask;
    size_t fg = 0, covered = 0;
    for (int y = 0; y < uni.height(); ++y)
      for (int x = 0; x < uni.width(); ++x) {
        const bool drawn = ours.at(x, y, 0) | ours.at(x, y, 1) | ours.at(x, y, 2);
        fg += mask.at(x, y) != 0;
        covered += mask.at(x, y) != 0 && drawn;
        if (!drawn) both.at(x, y) = 0;
        if (drawn) uni.at(x, y) = 255;
        if (uni.at(x, y) == 0) truth.at(x, y, 0) = truth.at(x, y, 1) = truth.at(x, y, 2) = 0;
      }
    HOLO_ASSIGN_OR_RETURN(double pu, holo::metrics::ComputePsnr(ours, truth, &uni));
    HOLO_ASSIGN_OR_RETURN(double po, holo::metrics::ComputePsnr(ours, truth, &both));
    psnr_overlap.push_back(po);
    coverage.push_back(fg ? static_cast<double>(covered) / static_cast<double>(fg) : 0.0);
    psnr.push_back(p);
    ssim.push_back(s);
    psnr_union.push_back(pu);
  }
  q->psnr = holo::bench::Mean(psnr);
  q->ssim = holo::bench::Mean(ssim);
  q->psnr_union = holo::bench::Mean(psnr_union);
  q->psnr_overlap = holo::bench::Mean(psnr_overlap);
  q->coverage = holo::bench::Mean(coverage);
  return holo::OkStatus();
}

// Side-by-side pictures for docs/viewer.md, one PNG per view: ground truth
// | projective texturing as before issue 17 (RenderSettings::Legacy: no
// masks) | projective texturing now, blended per pixel | the same baked into
// the atlas (the default) | per-vertex colour; each panel cropped to the
// true foreground's box (plus a margin) of that view.
holo::Status WriteSideBySide(holo::render::Renderer* renderer, holo::render::OffscreenTarget* target,
                             holo::SyntheticStudio* studio, int64_t frame, const holo::render::RenderSettings& base,
                             const std::string& prefix) {
  for (float az : {22.5f}) {
    const holo::CameraModel cam = OrbitCamera(target->width(), target->height(), az, 2.0f);
    holo::ImageRgb8 truth;
    holo::ImageGray8 mask;
    studio->RenderView(frame, cam, &truth, nullptr, &mask);
    std::vector<holo::ImageRgb8> panels = {truth};
    for (int k = 0; k < 4; ++k) {
      holo::render::RenderSettings settings = base;
      settings.background = {0, 0, 0};
      settings.mode = k == 3 ? holo::render::ColorMode::kVertexColor : holo::render::ColorMode::kProjective;
      settings.projective.bake = k == 2;
      if (k == 0) settings = holo::render::RenderSettings::Legacy();
      settings.background = {0, 0, 0};
      target->Bind();
      HOLO_RETURN_IF_ERROR(renderer->Render(cam, settings, {0, 0, target->width(), target->height()}));
      panels.emplace_back();
      HOLO_RETURN_IF_ERROR(target->ReadRgb(&panels.back()));
    }
    // The truth's background black too, so that only the person differs.
    for (int y = 0; y < truth.height(); ++y)
      for (int x = 0; x < truth.width(); ++x)
        if (mask.at(x, y) == 0) panels[0].at(x, y, 0) = panels[0].at(x, y, 1) = panels[0].at(x, y, 2) = 0;
    int x0 = truth.width(), y0 = truth.height(), x1 = -1, y1 = -1;
    for (int y = 0; y < truth.height(); ++y)
      for (int x = 0; x < truth.width(); ++x)
        if (mask.at(x, y)) {
          x0 = std::min(x0, x);
          x1 = std::max(x1, x);
          y0 = std::min(y0, y);
          y1 = std::max(y1, y);
        }
    if (x1 < 0) return holo::Internal("the person is not in view");
    x0 = std::max(0, x0 - 8);
    y0 = std::max(0, y0 - 8);
    x1 = std::min(truth.width() - 1, x1 + 8);
    y1 = std::min(truth.height() - 1, y1 + 8);
    const int pw = x1 - x0 + 1, ph = y1 - y0 + 1;
    const int n = static_cast<int>(panels.size());
    holo::ImageRgb8 out(n * pw + (n - 1) * 4, ph);
    std::fill(out.data(), out.data() + 3 * out.num_pixels(), uint8_t{255});
    for (int k = 0; k < n; ++k)
      for (int y = 0; y < ph; ++y)
        for (int x = 0; x < pw; ++x)
          for (int ch = 0; ch < 3; ++ch) out.at(k * (pw + 4) + x, y, ch) = panels[k].at(x0 + x, y0 + y, ch);
    HOLO_RETURN_IF_ERROR(
        holo::WriteImageRgb8(prefix + "_az" + std::to_string(static_cast<int>(az)) + ".png", out));
  }
  return holo::OkStatus();
}

// What the render figures compare: per-vertex colour, projective texturing
// blended per fragment, and the same baked once per mesh into an atlas.
constexpr std::pair<holo::render::ColorMode, bool> kVariants[] = {{holo::render::ColorMode::kVertexColor, false},
                                                                   {holo::render::ColorMode::kProjective, false},
                                                                   {holo::render::ColorMode::kProjective, true}};

// The content of --content: the truth (one mesh) or the fused stream (the
// site's full mesh and the reduced stream mesh).
holo::Status MakeContents(const holo::bench::BenchArgs& args, const ClientBenchOptions& options,
                          const holo::Workload& workload, std::vector<ViewerContent>* contents) {
  if (options.content == "truth") {
    holo::StudioOptions tso = workload.studio;
    tso.threads = 2;
    tso.color_variation = false;  // a server calibrates its pods
    HOLO_ASSIGN_OR_RETURN(auto tstudio, holo::SyntheticStudio::Create(workload.rig, tso));
    contents->emplace_back();
    return MakeTruthContent(workload, tstudio.get(), options.frame, &contents->back());
  }
  if (!args.json) spdlog::info("client: running the capture site to frame {}...", options.frame);
  contents->resize(2);
  holo::Stopwatch sw;
  holo::TextureOptions to;
  if (options.legacy == "1") to.mask_edge_px = 0;
  const int sequence_frames =
      options.parts.find("stream") != std::string::npos || options.parts.empty() ? options.video_frames : 0;
  HOLO_RETURN_IF_ERROR(MakeFusedContent(workload, options.frame, options.reduce, options.stream_step, to, options.behind_band,
                                        options.behind_sigmas,
                                        sequence_frames, options.content == "temporal", &(*contents)[0],
                                        &(*contents)[1]));
  if (!args.json) spdlog::info("client: site done in {:.1f} s", sw.ElapsedMs() / 1000);
  // The render part also draws the stream mesh as a G3 viewer has it (the
  // grid through the codec and marching cubes: more and thinner triangles
  // than the simplified mesh, no vertex colours), to compare what each
  // geometry codec's mesh costs the viewer per new frame.
  if ((options.parts.empty() || options.parts.find("render") != std::string::npos) && (*contents)[1].field.size() > 0) {
    ViewerContent g3 = (*contents)[1];
    std::vector<uint8_t> blob;
    HOLO_RETURN_IF_ERROR(holo::protocol::EncodeSurface(g3.field, holo::protocol::SurfaceEncodeOptions{}, &blob));
    HOLO_RETURN_IF_ERROR(holo::protocol::DecodeGeometry(blob, &g3.mesh));
    g3.mesh_name = "fused_stream_g3";
    g3.sequence_images.clear();
    g3.sequence_masks.clear();
    contents->push_back(std::move(g3));
  }
  return holo::OkStatus();
}

// What every part starts from: the workload, its studio (the truth's
// renders) and the content of --content.
struct PartInput {
  holo::Workload workload;
  std::unique_ptr<holo::SyntheticStudio> studio;
  std::vector<ViewerContent> contents;
};
holo::Status PreparePart(const holo::bench::BenchArgs& args, const ClientBenchOptions& options, PartInput* in) {
  HOLO_ASSIGN_OR_RETURN(in->workload, holo::GetWorkload(args.workload));
  holo::StudioOptions so = in->workload.studio;
  so.threads = 2;
  HOLO_ASSIGN_OR_RETURN(in->studio, holo::SyntheticStudio::Create(in->workload.rig, so));
  return MakeContents(args, options, in->workload, &in->contents);
}

int Fail(const holo::Status& s) {
  spdlog::error("client: {}", s.ToString());
  return 1;
}

int RunClientRenderPart(const holo::bench::BenchArgs& args, const ClientBenchOptions& options) {
  std::vector<std::pair<int, int>> resolutions;
  {
    std::stringstream ss(options.resolutions);
    std::string item;
    while (std::getline(ss, item, ',')) {
      int w = 0, h = 0;
      if (std::sscanf(item.c_str(), "%dx%d", &w, &h) != 2 || w < 16 || h < 16 || w > 8192 || h > 8192) {
        spdlog::error("client: --resolutions wants WxH[,WxH...] with sides in 16..8192, got '{}'", item);
        return 2;
      }
      resolutions.push_back({w, h});
    }
  }
  const std::string& png_dir = options.png_dir;
  const bool legacy = options.legacy == "1";
  const int frames = args.frames > 0 ? args.frames : 30;
  const int64_t studio_frame = options.frame;

  PartInput input;
  if (holo::Status s = PreparePart(args, options, &input); !s.ok()) return Fail(s);
  const holo::Workload* workload = &input.workload;
  const std::unique_ptr<holo::SyntheticStudio>* studio = &input.studio;
  std::vector<ViewerContent>& contents = input.contents;

  auto ctx = holo::render::CreateHeadlessContext();
  if (!ctx.ok()) return Fail(ctx.status());
  auto renderer = holo::render::Renderer::Create();
  if (!renderer.ok()) return Fail(renderer.status());
  const std::string gl_renderer = holo::render::CurrentGlRenderer();
  const char* lp_threads = std::getenv("LP_NUM_THREADS");
  if (!png_dir.empty()) {
    if (holo::Status s = holo::MakeDirs(png_dir); !s.ok()) return Fail(s);
  }

  for (const ViewerContent& c : contents) {
    const std::string tris = std::to_string(c.mesh.num_triangles());
    std::map<std::string, std::string> q = {{"stage", "render"},   {"content", c.content},
                                            {"mesh", c.mesh_name}, {"triangles", tris},
                                            {"renderer", gl_renderer}, {"pods", std::to_string(c.images.size())},
                                            {"frame", std::to_string(studio_frame)}};
    if (lp_threads) q["lp_num_threads"] = lp_threads;
    if (legacy) q["renderer_options"] = "legacy";
    holo::render::RenderSettings base;
    if (legacy) base = holo::render::RenderSettings::Legacy();
    if (options.cull == "0") {
      base.cull_back_faces = false;
      base.projective.cull_back_faces = false;
      q["cull_back_faces"] = "false";
    }
    if (!options.prepass.empty()) {
      base.depth_prepass = options.prepass == "1";
      q["depth_prepass"] = base.depth_prepass ? "true" : "false";
    }
    if (options.pods_per_vertex >= 0) base.projective.pods_per_vertex = options.pods_per_vertex;
    if (options.visibility_mm > 0) {
      base.projective.visibility_tolerance_m = options.visibility_mm * 1e-3f;
      q["visibility_mm"] = fmt::format("{:g}", options.visibility_mm);
    }
    if (options.bake_texels > 0) base.projective.bake_texels_per_edge = options.bake_texels;
    if (options.bake_density >= 0) base.projective.bake_texels_per_pod_pixel = options.bake_density;
    if (options.max_pods_per_triangle >= 0) base.projective.max_pods_per_triangle = options.max_pods_per_triangle;
    q["pods_per_vertex"] = std::to_string(base.projective.pods_per_vertex);
    q["max_pods_per_triangle"] = std::to_string(base.projective.max_pods_per_triangle);
    if (!options.gpu_visibility.empty()) base.projective.gpu_visibility = options.gpu_visibility == "1";
    q["visibility"] = base.projective.gpu_visibility ? "gl" : "cpu";
    if (!(*renderer)->SetRemoteMesh(c.mesh).ok()) return 1;
    if (holo::Status s = (*renderer)->SetPodImages(workload->rig, c.ImagePtrs(), c.MaskPtrs()); !s.ok())
      return Fail(s);
    // Quality from novel views.
    {
      auto small = holo::render::OffscreenTarget::Create(640, 480);
      if (!small.ok()) return Fail(small.status());
      for (const auto& [mode, bake] : kVariants) {
        holo::render::RenderSettings settings = base;
        settings.mode = mode;
        settings.projective.bake = bake;
        Quality qual;
        if (holo::Status s = MeasureQuality(renderer->get(), small->get(), studio->get(), studio_frame, settings,
                                            &qual);
            !s.ok())
          return Fail(s);
        auto qm = q;
        qm["mode"] = holo::render::ColorModeName(mode);
        if (mode == holo::render::ColorMode::kProjective) qm["baked"] = bake ? "true" : "false";
        qm["resolution"] = "640x480";
        qm["views"] = "4";
        qm["region"] = "truth";
        EmitFigure("client", args.workload, "novel_view_psnr_db", qual.psnr, "dB", qm);
        EmitFigure("client", args.workload, "novel_view_ssim", qual.ssim, "", qm);
        qm["region"] = "union";
        EmitFigure("client", args.workload, "novel_view_psnr_db", qual.psnr_union, "dB", qm);
        qm["region"] = "overlap";
        EmitFigure("client", args.workload, "novel_view_psnr_db", qual.psnr_overlap, "dB", qm);
        qm.erase("region");
        EmitFigure("client", args.workload, "novel_view_coverage", qual.coverage, "fraction", qm);
      }
      if (!png_dir.empty() && c.mesh_name != "fused_full") {
        if (holo::Status s = WriteSideBySide(renderer->get(), small->get(), studio->get(), studio_frame, base,
                                             png_dir + "/viewer_" + c.mesh_name);
            !s.ok())
          return Fail(s);
      }
    }
    // Per-stream-frame costs: upload of mesh + pod images, pod visibility maps.
    std::vector<double> upload_ms, vis_ms, vis_cpu;
    for (int r = 0; r < 5; ++r) {
      holo::Stopwatch sw;
      if (!(*renderer)->SetRemoteMesh(c.mesh).ok() ||
          !(*renderer)->SetPodImages(workload->rig, c.ImagePtrs(), c.MaskPtrs()).ok())
        return 1;
      holo::render::FinishGl();
      upload_ms.push_back(sw.ElapsedMs());
      sw.Restart();
      const double cpu0 = ProcessCpuMs();
      if (!(*renderer)->UpdateVisibility(base.projective).ok()) return 1;
      holo::render::FinishGl();
      vis_ms.push_back(sw.ElapsedMs());
      vis_cpu.push_back(ProcessCpuMs() - cpu0);
    }
    EmitFigure("client", args.workload, "upload_ms", Median(upload_ms), "ms", q);
    if (c.signed_mm.size() == 3) {
      static constexpr const char* kStats[3] = {"p10", "p50", "p90"};
      for (int k = 0; k < 3; ++k) {
        auto qs = q;
        qs["stat"] = kStats[k];
        EmitFigure("client", args.workload, "signed_distance_mm", c.signed_mm[k], "mm", qs);
      }
    }
    EmitFigure("client", args.workload, "visibility_ms", Median(vis_ms), "ms", q);
    EmitFigure("client", args.workload, "visibility_cpu_ms", Median(vis_cpu), "ms", q);
    // The atlas bake (per mesh, after visibility and the pod selection).
    {
      std::vector<double> bake_ms, bake_cpu;
      holo::render::ProjectiveOptions po = base.projective;
      po.bake = true;
      for (int r = 0; r < 5; ++r) {
        if (!(*renderer)->SetRemoteMesh(c.mesh).ok() ||
            !(*renderer)->SetPodImages(workload->rig, c.ImagePtrs(), c.MaskPtrs()).ok() ||
            !(*renderer)->UpdateVisibility(po).ok())
          return 1;
        holo::render::FinishGl();
        // The pod selection first (timed on its own below), then the bake
        // alone.
        if (!(*renderer)->UpdateAtlas(po).ok()) return 1;
        const double cpu0 = ProcessCpuMs();
        holo::Stopwatch sw;
        if (holo::Status s = (*renderer)->UpdateAtlas(po); !s.ok()) return Fail(s);
        holo::render::FinishGl();
        bake_ms.push_back(sw.ElapsedMs());
        bake_cpu.push_back(ProcessCpuMs() - cpu0);
      }
      const auto& st = (*renderer)->atlas_stats();
      auto qb = q;
      qb["texels_per_edge"] = std::to_string(st.texels_per_edge);  // as baked (halved if the atlas did not fit)
      if (st.fallback) qb["fallback"] = "per-fragment";
      qb["texels_per_pod_pixel"] = fmt::format("{:g}", base.projective.bake_texels_per_pod_pixel);
      qb["atlas"] = std::to_string(st.width) + "x" + std::to_string(st.height);
      EmitFigure("client", args.workload, "bake_ms", Median(bake_ms), "ms", qb);
      EmitFigure("client", args.workload, "bake_cpu_ms", Median(bake_cpu), "ms", qb);
      EmitFigure("client", args.workload, "bake_texels", static_cast<double>(st.texels), "", qb);
      EmitFigure("client", args.workload, "bake_samples", static_cast<double>(st.samples), "", qb);
    }
    for (const auto& [width, height] : resolutions) {
      auto target = holo::render::OffscreenTarget::Create(width, height);
      if (!target.ok()) return Fail(target.status());
      for (const auto& [mode, bake] : kVariants) {
        holo::render::RenderSettings settings = base;
        settings.mode = mode;
        settings.projective.bake = bake;
        (*target)->Bind();
        std::vector<double> ms, cpu;
        for (int i = -5; i < frames; ++i) {  // 5 warm-up frames
          const holo::CameraModel cam = OrbitCamera(width, height, 3.0f * static_cast<float>(i), 2.5f);
          const double cpu0 = ProcessCpuMs();
          holo::Stopwatch sw;
          if (holo::Status s = (*renderer)->Render(cam, settings, {0, 0, width, height}); !s.ok()) return Fail(s);
          holo::render::FinishGl();
          if (i >= 0) {
            ms.push_back(sw.ElapsedMs());
            cpu.push_back(ProcessCpuMs() - cpu0);
          }
        }
        auto qm = q;
        qm["mode"] = holo::render::ColorModeName(mode);
        if (mode == holo::render::ColorMode::kProjective) qm["baked"] = bake ? "true" : "false";
        qm["frames"] = std::to_string(frames);
        qm["resolution"] = std::to_string(width) + "x" + std::to_string(height);
        EmitFigure("client", args.workload, "render_ms", Median(ms), "ms", qm);
        EmitFigure("client", args.workload, "render_cpu_ms", Median(cpu), "ms", qm);
        if (mode != holo::render::ColorMode::kProjective || !bake) continue;
        // What a live viewer pays per new frame: the mesh and the pods'
        // images set (normals, mask weights), visibility, pod selection,
        // bake, uploads and one draw; all of the process's threads (pool,
        // llvmpipe) in the CPU figure.
        ms.clear();
        cpu.clear();
        for (int i = -2; i < 10; ++i) {
          const holo::CameraModel cam = OrbitCamera(width, height, 3.0f * static_cast<float>(i), 2.5f);
          const double cpu0 = ProcessCpuMs();
          holo::Stopwatch sw;
          if (holo::Status s = (*renderer)->SetRemoteMesh(c.mesh); !s.ok()) return Fail(s);
          if (holo::Status s = (*renderer)->SetPodImages(workload->rig, c.ImagePtrs(), c.MaskPtrs()); !s.ok())
            return Fail(s);
          if (holo::Status s = (*renderer)->Render(cam, settings, {0, 0, width, height}); !s.ok()) return Fail(s);
          holo::render::FinishGl();
          if (i >= 0) {
            ms.push_back(sw.ElapsedMs());
            cpu.push_back(ProcessCpuMs() - cpu0);
          }
        }
        qm["per"] = "new mesh";
        qm["frames"] = "10";
        EmitFigure("client", args.workload, "mesh_render_ms", Median(ms), "ms", qm);
        EmitFigure("client", args.workload, "mesh_render_cpu_ms", Median(cpu), "ms", qm);
      }
    }
    // The per-mesh pod selection behind the projective frames above.
    const auto& sel = (*renderer)->selection_stats();
    EmitFigure("client", args.workload, "pod_sets", static_cast<double>(sel.draws), "", q);
    EmitFigure("client", args.workload, "mean_pods_per_triangle", sel.mean_pods, "", q);
    EmitFigure("client", args.workload, "capped_triangles", static_cast<double>(sel.capped_triangles), "", q);
    if (const double share = UsedPixelShare(workload->rig, c.mesh, (*renderer)->triangle_pods(), c.masks); share >= 0) {
      auto qu = q;
      qu["pods_per_vertex"] = std::to_string(base.projective.pods_per_vertex);
      EmitFigure("client", args.workload, "used_pixel_share", share, "", qu);
    }
    EmitFigure("client", args.workload, "select_ms", sel.select_ms, "ms", q);
    {
      auto qs = q;
      qs["thread"] = "caller";  // the pool's other threads are not counted
      EmitFigure("client", args.workload, "select_cpu_ms", sel.select_cpu_ms, "ms", qs);
    }
  }
  return 0;
}

// What the stream costs the viewer's picture: the stream mesh and the pods'
// images through the site's codecs as the live server sends them — each
// quality layer of SitePublisher (layer 0 full, layer 1 reduced: coarser
// G1 step, lower C1 quality, every n-th frame) — rendered projectively
// (baked) from the novel views, against the same render from the
// uncompressed mesh and images: `viewer_psnr_loss_db` per `codec` and
// `layer`, with the layer's `stream_mbps` at 30 fps (one frame's bytes ×
// its frame rate). V1 video (fused content) codes the `video_frames`
// frames up to the measured one, as a live encoder sees them (the reduced
// layer every frame_divisor-th), and the measured frame's decoded images
// are rendered; its bytes per frame are those of one keyframe interval:
// (keyframe + (interval − 1) × mean delta frame) / interval.
int RunClientStreamPart(const holo::bench::BenchArgs& args, const ClientBenchOptions& options) {
  PartInput input;
  if (holo::Status s = PreparePart(args, options, &input); !s.ok()) return Fail(s);
  const holo::Workload* workload = &input.workload;
  const std::unique_ptr<holo::SyntheticStudio>* studio = &input.studio;
  std::vector<ViewerContent>& contents = input.contents;
  // The mesh a viewer gets: the truth, or the fused stream-size mesh.
  ViewerContent& c = contents.size() > 1 ? contents[1] : contents[0];
  if (c.raw_images.empty()) {  // truth: the pods' whole images are the reference
    c.raw_images = c.images;
    c.raw_masks.assign(c.images.size(), holo::ImageGray8());
  }
  auto ctx = holo::render::CreateHeadlessContext();
  if (!ctx.ok()) return Fail(ctx.status());
  auto renderer = holo::render::Renderer::Create();
  if (!renderer.ok()) return Fail(renderer.status());
  auto small = holo::render::OffscreenTarget::Create(640, 480);
  if (!small.ok()) return Fail(small.status());
  holo::render::RenderSettings settings;
  settings.mode = holo::render::ColorMode::kProjective;
  settings.projective.bake = true;

  holo::net::SitePublisherOptions publisher;  // the live server's defaults
  if (options.reduced_step_scale > 0) publisher.reduced.position_step_scale = options.reduced_step_scale;
  if (options.g3_step_mm > 0) publisher.surface.position_step_m = static_cast<float>(options.g3_step_mm * 1e-3);
  if (holo::Status s = publisher.surface.Check(); !s.ok()) return Fail(s.WithContext("--g3-step-mm"));
  if (options.reduced_jpeg_quality > 0) publisher.reduced.jpeg_quality = options.reduced_jpeg_quality;
  struct Variant {
    std::string codec;
    int layer;  // -1: uncompressed
    holo::protocol::GeometryEncodeOptions geometry;
    holo::protocol::ColorEncodeOptions color;
    double fps;
    bool video = false;  // V1 instead of `color`
    holo::protocol::VideoEncodeOptions video_options;
    bool g3 = false;  // G3 (the stream mesh's grid) instead of `geometry`
    holo::protocol::SurfaceEncodeOptions surface;
  };
  std::vector<Variant> variants;
  variants.push_back({"none", -1, publisher.geometry, publisher.color_options, 30.0, false, publisher.video, false, {}});
  const int divisor = publisher.reduced.frame_divisor;
  for (int layer = 0; layer < 2; ++layer) {
    const holo::net::LayerEncodeOptions lo = holo::net::EncodeOptionsOfLayer(publisher, layer);
    variants.push_back({"G1+C1", layer, lo.geometry, lo.color, layer == 0 ? 30.0 : 30.0 / divisor, false, lo.video, false, {}});
  }
  // G3 where the content has the stream mesh's grid (fused).
  const bool g3 = c.field.size() > 0;
  if (g3) {
    for (int layer = 0; layer < 2; ++layer) {
      const holo::net::LayerEncodeOptions lo = holo::net::EncodeOptionsOfLayer(publisher, layer);
      variants.push_back({"G3+C1", layer, lo.geometry, lo.color, layer == 0 ? 30.0 : 30.0 / divisor, false, lo.video,
                          true, lo.surface});
    }
  }
  const int sequence = static_cast<int>(c.sequence_images.size());
  if (sequence > 0) {
    std::stringstream ss(options.video_crfs);
    std::string item;
    while (std::getline(ss, item, ',')) {
      holo::net::SitePublisherOptions vp = publisher;
      vp.color_options.codec = holo::protocol::ColorCodec::kV1;
      try {
        vp.video.crf = std::stoi(item);
      } catch (const std::exception&) {
        spdlog::error("client: --video-crfs wants numbers 0..51, got '{}'", item);
        return 2;
      }
      if (!options.video_preset.empty()) vp.video.preset = options.video_preset;
      if (!options.video_chroma.empty()) vp.video.chroma_444 = options.video_chroma == "444";
      if (holo::Status s = vp.video.Check(); !s.ok()) return Fail(s);
      for (int layer = 0; layer < 2; ++layer) {
        const holo::net::LayerEncodeOptions lo = holo::net::EncodeOptionsOfLayer(vp, layer);
        Variant v{"G1+V1", layer, lo.geometry, lo.color, layer == 0 ? 30.0 : 30.0 / divisor, true, lo.video, false, {}};
        variants.push_back(v);
        if (g3) {
          v.codec = "G3+V1";
          v.g3 = true;
          v.surface = lo.surface;
          variants.push_back(v);
        }
      }
    }
  } else if (c.content != "truth" && options.video_frames > 0) {
    spdlog::warn("client: no frame sequence for V1 (stream part)");
  }
  double reference_psnr = 0, reference_ssim = 0;
  for (const Variant& v : variants) {
    holo::Mesh mesh = c.mesh;
    std::vector<holo::ImageRgb8> images = c.raw_images;
    std::vector<holo::ImageGray8> masks = c.raw_masks;
    size_t geometry_bytes = 0, color_bytes = 0, connectivity_bytes = 0;
    if (v.layer >= 0) {
      std::vector<uint8_t> blob;
      holo::protocol::GeometryEncodeOptions g = v.geometry;
      g.colors = false;  // projective texturing: the live server sends no vertex colours with images
      if (holo::Status s = v.g3 ? holo::protocol::EncodeSurface(c.field, v.surface, &blob)
                                : holo::protocol::EncodeGeometry(c.mesh, g, &blob);
          !s.ok())
        return Fail(s);
      geometry_bytes = blob.size();
      if (holo::Status s = holo::protocol::DecodeGeometry(blob, &mesh); !s.ok()) return Fail(s);
      // G1 (PROTOCOL.md §7): 12-byte prefix, origin, step, chroma shift,
      // then the connectivity stream's blob32 (read after the decode checked the blob).
      constexpr size_t kConnectivityAt = 12 + 4 * 4 + 1;
      uint32_t connectivity = 0;
      if (blob[0] == 2 && blob.size() >= kConnectivityAt &&
          holo::protocol::ByteReader(std::span<const uint8_t>(blob).subspan(kConnectivityAt))
              .U32("g1.connectivity", &connectivity)
              .ok())
        connectivity_bytes = connectivity;
      if (!v.video) {
        for (size_t i = 0; i < images.size(); ++i) {
          blob.clear();
          if (holo::Status s = holo::protocol::EncodeColor(c.raw_images[i], c.raw_masks[i], v.color, &blob); !s.ok())
            return Fail(s);
          color_bytes += blob.size();
          holo::ImageGray8 mask;
          if (holo::Status s = holo::protocol::DecodeColor(blob, &images[i], &mask); !s.ok()) return Fail(s);
          if (!masks[i].empty()) masks[i] = std::move(mask);
        }
      } else {
        // Each pod's stream over the sequence, ending at the measured frame.
        const int step = v.layer == 0 ? 1 : divisor;
        const int first = (sequence - 1) % step;
        double key_bytes = 0, delta_bytes = 0;
        int deltas = 0;
        for (size_t i = 0; i < images.size(); ++i) {
          auto enc = holo::protocol::VideoEncoder::Create(v.video_options);
          if (!enc.ok()) return Fail(enc.status());
          holo::protocol::VideoDecoder dec;
          for (int k = first; k < sequence; k += step) {
            blob.clear();
            if (holo::Status s = (*enc)->Encode(c.sequence_images[k][i], c.sequence_masks[k][i], &blob); !s.ok())
              return Fail(s);
            if (k == first) {
              key_bytes += static_cast<double>(blob.size());
            } else {
              delta_bytes += static_cast<double>(blob.size());
              if (i == 0) ++deltas;  // frames, not pod frames
            }
            if (holo::Status s = dec.Decode(blob); !s.ok()) return Fail(s);
          }
          images[i] = dec.image();
          masks[i] = dec.mask();
        }
        const double interval = v.video_options.keyframe_interval;
        const double mean_delta = deltas > 0 ? delta_bytes / deltas : key_bytes;  // all pods' bytes per frame
        color_bytes = static_cast<size_t>(std::lround((key_bytes + (interval - 1) * mean_delta) / interval));
      }
    }
    if (holo::Status s = (*renderer)->SetRemoteMesh(mesh); !s.ok()) return Fail(s);
    std::vector<const holo::ImageRgb8*> ip;
    std::vector<const holo::ImageGray8*> mp;
    for (size_t i = 0; i < images.size(); ++i) {
      ip.push_back(&images[i]);
      if (!masks[i].empty()) mp.push_back(&masks[i]);  // truth: whole images, no masks
    }
    if (holo::Status s = (*renderer)->SetPodImages(workload->rig, ip, mp); !s.ok()) return Fail(s);
    Quality qual;
    if (holo::Status s = MeasureQuality(renderer->get(), small->get(), studio->get(), options.frame, settings, &qual);
        !s.ok())
      return Fail(s);
    std::map<std::string, std::string> q = {{"stage", "stream"},       {"content", c.content},
                                            {"mesh", c.mesh_name},     {"triangles", std::to_string(c.mesh.num_triangles())},
                                            {"codec", v.codec},        {"mode", "projective"},
                                            {"baked", "true"},         {"resolution", "640x480"},
                                            {"views", "4"},            {"region", "truth"},
                                            {"frame", std::to_string(options.frame)}};
    // Truth content has the pods' whole images (no masks): its bytes are not the live stream's.
    q["pod_images"] = c.raw_masks.empty() || c.raw_masks[0].empty() ? "whole" : "masked";
    if (v.layer >= 0) {
      q["layer"] = v.layer == 0 ? "full" : "reduced";
      if (v.g3) {
        q["g3_step_mm"] = fmt::format("{:g}", v.surface.position_step_m * 1e3);
        q["decoded_triangles"] = std::to_string(mesh.num_triangles());
      } else {
        q["position_step_mm"] = fmt::format("{:g}", v.geometry.position_step_m * 1e3);
      }
      if (v.video) {
        q["video_crf"] = std::to_string(v.video_options.crf);
        q["video_library"] = holo::protocol::VideoLibraryName(v.video_options.library);
        q["chroma"] = v.video_options.chroma_444 ? "444" : "420";
        q["video_frames"] = std::to_string(sequence);
        q["keyframe_interval"] = std::to_string(v.video_options.keyframe_interval);
      } else {
        q["jpeg_quality"] = std::to_string(v.color.jpeg_quality);
      }
      q["fps"] = fmt::format("{:g}", v.fps);
    }
    EmitFigure("client", args.workload, "novel_view_psnr_db", qual.psnr, "dB", q);
    EmitFigure("client", args.workload, "novel_view_ssim", qual.ssim, "", q);
    if (v.layer < 0) {
      reference_psnr = qual.psnr;
      reference_ssim = qual.ssim;
      continue;
    }
    EmitFigure("client", args.workload, "viewer_psnr_loss_db", reference_psnr - qual.psnr, "dB", q);
    EmitFigure("client", args.workload, "viewer_ssim_loss", reference_ssim - qual.ssim, "", q);
    EmitFigure("client", args.workload, "geometry_bytes", static_cast<double>(geometry_bytes), "B", q);
    EmitFigure("client", args.workload, "geometry_connectivity_bytes", static_cast<double>(connectivity_bytes), "B", q);
    EmitFigure("client", args.workload, "color_bytes", static_cast<double>(color_bytes), "B", q);
    EmitFigure("client", args.workload, "stream_mbps",
               static_cast<double>(geometry_bytes + color_bytes) * 8.0 * v.fps / 1e6, "Mbit/s", q);
  }
  return 0;
}

struct Part {
  const char* name;
  int (*run)(const holo::bench::BenchArgs&, const ClientBenchOptions&);
};

const std::vector<Part>& Parts() {
  static const std::vector<Part> parts = {{"render", RunClientRenderPart}, {"stream", RunClientStreamPart}};
  return parts;
}

int RunClientBench(const holo::bench::BenchArgs& args, const ClientBenchOptions& options) {
  std::set<std::string> selected;
  {
    std::stringstream ss(options.parts);
    std::string item;
    while (std::getline(ss, item, ',')) selected.insert(item);
  }
  for (const std::string& s : selected) {
    if (std::none_of(Parts().begin(), Parts().end(), [&](const Part& p) { return s == p.name; })) {
      spdlog::error("client: unknown part '{}'", s);
      return 2;
    }
  }
  for (const Part& p : Parts()) {
    if (!selected.empty() && !selected.count(p.name)) continue;
    if (int rc = p.run(args, options); rc != 0) return rc;
  }
  return 0;
}

holo::bench::BenchFn SetupClient(CLI::App& app) {
  holo::bench::DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto o = std::make_shared<ClientBenchOptions>();
  app.add_option("--parts", o->parts, "run only these parts, comma-separated (render, stream); default all");
  app.add_option("--resolutions", o->resolutions, "render sizes WxH[,WxH...], sides 16..8192")->capture_default_str();
  app.add_option("--content", o->content,
                 "fused (the capture site's mesh and images), temporal (the same with the site's temporal fusion, "
                 "holoport-server --temporal) or truth (the studio's)")
      ->check(CLI::IsMember({"fused", "temporal", "truth"}))
      ->capture_default_str();
  app.add_option("--png-dir", o->png_dir, "write the novel views as PNGs to this directory");
  app.add_option("--legacy", o->legacy, "1: the renderer's legacy settings, no mask-edge texturing")
      ->check(CLI::IsMember({"0", "1"}))
      ->capture_default_str();
  app.add_option("--frame", o->frame, "studio frame of the content")
      ->check(CLI::Range(1, 10000))
      ->capture_default_str();
  app.add_option("--reduce", o->reduce, "fused: triangle budget of the site's stream mesh (default: the workload's, as holoport-server)");
  app.add_option("--stream-step", o->stream_step, "fused: the stream mesh's grid step in voxels (holoport-server --stream-step)")
      ->capture_default_str()
      ->check(CLI::Range(2, 4));
  app.add_option("--cull", o->cull, "0: no back-face culling")->check(CLI::IsMember({"0", "1"}))->capture_default_str();
  app.add_option("--prepass", o->prepass, "1 / 0: depth pre-pass on / off (default: the renderer's)")
      ->check(CLI::IsMember({"0", "1"}));
  app.add_option("--visibility-mm", o->visibility_mm,
                 "projective: a point is visible from a pod when at most this far behind its depth map, mm "
                 "(default: the renderer's)")
      ->check(CLI::Range(1.0, 200.0));
  app.add_option("--pods-per-vertex", o->pods_per_vertex,
                 "pods each vertex keeps for projective texturing, 0 = all (default: the renderer's)")
      ->check(CLI::Range(0, holo::render::Renderer::kMaxPods));
  app.add_option("--max-pods-per-triangle", o->max_pods_per_triangle,
                 "pods a triangle is textured from at most (default: the renderer's)")
      ->check(CLI::Range(1, holo::render::Renderer::kMaxPods));
  app.add_option("--bake-texels", o->bake_texels,
                 "atlas texels along a triangle's edge for the baked projective mode (default: the renderer's)")
      ->check(CLI::Range(1, 16));
  app.add_option("--bake-density", o->bake_density,
                 "atlas texels per pod pixel of a triangle's edge, 0 = always --bake-texels (default: the renderer's)")
      ->check(CLI::Range(0.0, 64.0));
  app.add_option("--behind-band", o->behind_band,
                 "fused content: the site's TSDF counts observations behind the surface this many truncation "
                 "distances deep (default: TsdfOptions')")
      ->check(CLI::Range(1.0, 4.0));
  app.add_option("--behind-sigmas", o->behind_sigmas,
                 "fused content: and this many σ of the sensor's depth noise at each pixel's depth deeper "
                 "(default: TsdfOptions'; 0 = a fixed band)")
      ->check(CLI::Range(0.0, 5.0));
  app.add_option("--gpu-visibility", o->gpu_visibility,
                 "1 / 0: the pods' visibility maps rendered by GL / rasterized on the CPU (default: the renderer's)")
      ->check(CLI::IsMember({"0", "1"}));
  app.add_option("--g3-step-mm", o->g3_step_mm, "stream part: G3's position step along a grid edge, mm");
  app.add_option("--reduced-step-scale", o->reduced_step_scale,
                 "stream part: the reduced layer's G1 step x this (default: holoport-server's)")
      ->check(CLI::Range(1.0, 16.0));
  app.add_option("--reduced-jpeg-quality", o->reduced_jpeg_quality,
                 "stream part: the reduced layer's C1 quality (default: holoport-server's)")
      ->check(CLI::Range(1, 100));
  app.add_option("--video-frames", o->video_frames,
                 "stream part, fused: frames of V1 video coded up to the measured frame (0: no V1)")
      ->check(CLI::Range(0, 300))
      ->capture_default_str();
  app.add_option("--video-crfs", o->video_crfs, "stream part: the full layer's V1 CRFs to measure, comma-separated")
      ->capture_default_str();
  app.add_option("--video-preset", o->video_preset,
                 "stream part: V1's encoder preset (x264: ultrafast..veryslow; default: the live server's)");
  app.add_option("--video-chroma", o->video_chroma, "stream part: V1's chroma, 444 or 420 (default: the live server's)")
      ->check(CLI::IsMember({"444", "420"}));
  return [o](const holo::bench::BenchArgs& args) { return RunClientBench(args, *o); };
}

}  // namespace

HOLO_REGISTER_BENCH_OPTIONS("client",
                            "viewer: render_ms at 1280x720 (per-vertex colour, projective texturing), novel-view PSNR",
                            SetupClient);
