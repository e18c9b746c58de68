#include "studio/stereo_render.h"

#include <algorithm>
#include <cmath>

#include "common/worker_pool.h"
#include "studio/render.h"

namespace holo {

Status StereoRenderOptions::Check() const {
  if (!(ambient >= 0.0f && ambient <= 10.0f)) return InvalidArgument("ambient must be in [0, 10], got " + FormatNumber(ambient));
  if (!(albedo > 0.0f && albedo <= 1.0f)) return InvalidArgument("albedo must be in (0, 1], got " + FormatNumber(albedo));
  if (!(read_noise >= 0.0f && read_noise <= 100.0f))
    return InvalidArgument("read_noise must be in [0, 100], got " + FormatNumber(read_noise));
  if (!(shot_noise >= 0.0f && shot_noise <= 10.0f))
    return InvalidArgument("shot_noise must be in [0, 10], got " + FormatNumber(shot_noise));
  if (supersample < 1 || supersample > 4)
    return InvalidArgument("supersample must be in [1, 4], got " + FormatNumber(supersample));
  return OkStatus();
}

Rig WithStereoPods(const Rig& rig, double baseline_m) {
  Rig out = rig;
  for (auto& pod : out.pods) {
    if (pod.stereo.enabled) continue;
    pod.stereo.enabled = true;
    pod.stereo.ir = pod.depth;
    pod.stereo.ir.distortion = {0, 0, 0, 0, 0};
    pod.stereo.baseline_m = baseline_m;
  }
  return out;
}

namespace {

// The projector's dot pattern, tabulated over tan(angle) ∈ [-kTanRange, kTanRange]².
struct SpecklePattern {
  static constexpr float kTanRange = 1.2f;
  static constexpr int kTexelsPerCell = 3;
  int size = 0;
  float texels_per_tan = 0;
  std::vector<float> v;

  void Build(double pitch_mrad, double density, uint64_t seed) {
    const float pitch = static_cast<float>(pitch_mrad) * 1e-3f;  // tan units per cell near the axis
    const int cells = std::min(1400, static_cast<int>(std::ceil(2.0f * kTanRange / pitch)));
    size = cells * kTexelsPerCell;
    texels_per_tan = static_cast<float>(size) / (2.0f * kTanRange);
    v.assign(static_cast<size_t>(size) * size, 0.0f);
    const float sigma = 0.25f * kTexelsPerCell, inv2s2 = 1.0f / (2.0f * sigma * sigma);
    const uint64_t threshold = static_cast<uint64_t>(density * 4294967296.0);
    for (int cy = 0; cy < cells; ++cy) {
      for (int cx = 0; cx < cells; ++cx) {
        const uint64_t h = studio::HashOf(seed, static_cast<uint64_t>(cx), static_cast<uint64_t>(cy), 0x5BECULL);
        if ((h & 0xffffffffULL) >= threshold) continue;
        const float jx = ((h >> 32) & 0xff) / 255.0f - 0.5f, jy = ((h >> 40) & 0xff) / 255.0f - 0.5f;
        const float bright = 0.6f + 0.4f * (((h >> 48) & 0xff) / 255.0f);
        const float px = (cx + 0.5f + 0.5f * jx) * kTexelsPerCell, py = (cy + 0.5f + 0.5f * jy) * kTexelsPerCell;
        // ±3σ around the dot.
        const int x0 = std::max(0, static_cast<int>(px) - kTexelsPerCell);
        const int x1 = std::min(size - 1, static_cast<int>(px) + kTexelsPerCell + 1);
        const int y0 = std::max(0, static_cast<int>(py) - kTexelsPerCell);
        const int y1 = std::min(size - 1, static_cast<int>(py) + kTexelsPerCell + 1);
        for (int y = y0; y <= y1; ++y)
          for (int x = x0; x <= x1; ++x) {
            const float dx = x - px, dy = y - py;
            float& t = v[static_cast<size_t>(y) * size + x];
            t = std::min(1.0f, t + bright * std::exp(-(dx * dx + dy * dy) * inv2s2));
          }
      }
    }
  }

  // Bilinear lookup at projector direction (u, v) = (x/z, y/z); 0 outside.
  float Sample(float u, float w) const {
    const float fx = (u + kTanRange) * texels_per_tan - 0.5f, fy = (w + kTanRange) * texels_per_tan - 0.5f;
    if (!(fx >= 0.0f && fy >= 0.0f && fx < size - 1 && fy < size - 1)) return 0.0f;
    const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
    const float ax = fx - ix, ay = fy - iy;
    const float* r0 = v.data() + static_cast<size_t>(iy) * size + ix;
    const float* r1 = r0 + size;
    return (r0[0] * (1 - ax) + r0[1] * ax) * (1 - ay) + (r1[0] * (1 - ax) + r1[1] * ax) * ay;
  }
};

// Standard normal from a 64-bit hash (Box–Muller on its two halves).
inline float GaussFromHash(uint64_t h) {
  const float u1 = ((h & 0xffffffffULL) + 1.0f) * (1.0f / 4294967297.0f);
  const float u2 = (h >> 40) * (1.0f / 16777216.0f);
  return std::sqrt(-2.0f * std::log(u1)) * std::cos(6.2831853f * u2);
}

}  // namespace

struct StereoStudioRenderer::Impl {
  struct PodViews {
    // Set up on the pod's first render (ready): a renderer that serves one
    // pod (a network pod's process) does not hold the other pods' views,
    // ~10 MB each at QVGA with 2×2 supersampling.
    bool ready = false;
    studio::ViewCache left_ss, right_ss;  // supersampled IR views
    studio::ViewCache left_truth;         // output resolution, for the truth
    const SpecklePattern* pattern = nullptr;
  };
  std::vector<PodViews> pods;
  // Pods of one projector model (same pitch and density) share its pattern,
  // as projectors with the same diffractive element do.
  std::vector<std::unique_ptr<SpecklePattern>> patterns;
  std::vector<std::pair<double, double>> pattern_params;
  std::vector<studio::RenderScratch> scratch;

  // Renders `pod`'s pair (views `v`) of the posed frame into `p` with scratch buffers `s`.
  void RenderPair(const PodCalibration& pod, PodViews& v, const StereoRenderOptions& options, int64_t frame_index,
                  const studio::SceneTemplate& tmpl, const studio::FrameScene& scene, studio::RenderScratch& s,
                  StereoPair* p);
};

StereoStudioRenderer::StereoStudioRenderer(SyntheticStudio* studio, Rig rig_in, StereoRenderOptions options)
    : studio_(studio), rig_(std::move(rig_in)), options_(options), impl_(std::make_unique<Impl>()) {
  const Rig& rig = rig_;
  impl_->pods.resize(rig.pods.size());
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    const PodCalibration& pod = rig.pods[i];
    Impl::PodViews& v = impl_->pods[i];
    const std::pair<double, double> key(pod.stereo.projector.dot_pitch_mrad, pod.stereo.projector.dot_density);
    size_t k = 0;
    while (k < impl_->pattern_params.size() && impl_->pattern_params[k] != key) ++k;
    if (k == impl_->pattern_params.size()) {
      impl_->patterns.push_back(std::make_unique<SpecklePattern>());
      impl_->patterns.back()->Build(key.first, key.second, studio::HashOf(options_.seed, k, 0x9A77ULL));
      impl_->pattern_params.push_back(key);
    }
    v.pattern = impl_->patterns[k].get();
  }
}

StereoStudioRenderer::~StereoStudioRenderer() = default;

StatusOr<std::unique_ptr<StereoStudioRenderer>> StereoStudioRenderer::Create(SyntheticStudio* studio, Rig rig,
                                                                             StereoRenderOptions options) {
  if (studio == nullptr) return InvalidArgument("stereo renderer: no studio");
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("stereo render options"));
  HOLO_RETURN_IF_ERROR(rig.Check().WithContext("stereo rig"));
  if (rig.pods.size() != studio->rig().pods.size())
    return InvalidArgument("stereo rig has " + std::to_string(rig.pods.size()) + " pods, the studio's " +
                           std::to_string(studio->rig().pods.size()));
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    if (!rig.pods[i].world_from_depth.matrix().isApprox(studio->rig().pods[i].world_from_depth.matrix(), 1e-5f))
      return InvalidArgument("pods[" + std::to_string(i) + "]: stereo rig pose differs from the studio's");
  }
  for (const auto& pod : rig.pods) {
    if (!pod.stereo.enabled)
      return InvalidArgument("pods[" + std::to_string(pod.id) + "]: not a stereo pod (no 'stereo' block in the rig)");
    HOLO_RETURN_IF_ERROR(pod.stereo.Check().WithContext("pods[" + std::to_string(pod.id) + "].stereo"));
  }
  return std::unique_ptr<StereoStudioRenderer>(new StereoStudioRenderer(studio, std::move(rig), options));
}

namespace {

// Writes the IR image of the last render of `view` (supersampled by `ss`)
// into `out`. `right_offset_x`: the camera's offset from the left IR camera
// along x (0 for the left view, baseline for the right one).
void ShadeIr(const studio::ViewCache& view, const studio::RenderScratch& s, int ss, float right_offset_x,
             const PodCalibration& pod, const SpecklePattern& pattern, const StereoRenderOptions& o,
             uint64_t stream, ImageGray8* out) {
  const Intrinsics& k = view.camera.intrinsics;
  const int W = k.width / ss, H = k.height / ss;
  if (out->width() != W || out->height() != H) out->Resize(W, H);
  const Eigen::Vector3f proj = pod.stereo.projector.position;
  const float power = static_cast<float>(pod.stereo.projector.power_at_1m);
  const float inv_fx = 1.0f / static_cast<float>(k.fx), inv_fy = 1.0f / static_cast<float>(k.fy);
  const float cx = static_cast<float>(k.cx), cy = static_cast<float>(k.cy);
  const float norm = 255.0f * o.albedo / static_cast<float>(ss * ss);
  for (int y = 0; y < H; ++y) {
    uint8_t* row = out->row(y);
    for (int x = 0; x < W; ++x) {
      float sum = 0.0f;
      for (int sy = 0; sy < ss; ++sy) {
        const int py = y * ss + sy;
        for (int sx = 0; sx < ss; ++sx) {
          const int px = x * ss + sx;
          const size_t i = static_cast<size_t>(py) * k.width + px;
          const float z = s.out_z[i];
          float lit = o.ambient;
          if (std::isfinite(z) && z > 0.0f) {
            // Surface point in the left IR camera's frame, then seen from the projector.
            const Eigen::Vector3f q((px - cx) * inv_fx * z + right_offset_x - proj.x(), (py - cy) * inv_fy * z - proj.y(),
                                    z - proj.z());
            if (q.z() > 1e-3f) {
              const float r2 = q.squaredNorm();
              lit += power * pattern.Sample(q.x() / q.z(), q.y() / q.z()) * s.out_cos[i] / r2;
            }
          }
          sum += lit;
        }
      }
      float value = sum * norm;
      if (o.noise) {
        const uint64_t h = studio::HashOf(stream, static_cast<uint64_t>(y) * 65536u + static_cast<uint64_t>(x));
        const float sigma = std::sqrt(o.read_noise * o.read_noise + o.shot_noise * o.shot_noise * std::max(value, 0.0f));
        value += sigma * GaussFromHash(h);
      }
      row[x] = static_cast<uint8_t>(std::clamp(std::lround(value), 0L, 255L));
    }
  }
}

}  // namespace

void StereoStudioRenderer::Impl::RenderPair(const PodCalibration& pod, PodViews& v, const StereoRenderOptions& options,
                                            int64_t frame_index, const studio::SceneTemplate& tmpl,
                                            const studio::FrameScene& scene, studio::RenderScratch& s, StereoPair* p) {
  const int ss = options.supersample;
  if (!v.ready) {
    CameraModel l = pod.LeftIrCamera(), r = pod.RightIrCamera();
    v.left_truth.Init(l);
    l.intrinsics = l.intrinsics.Scaled(ss);
    r.intrinsics = r.intrinsics.Scaled(ss);
    v.left_ss.Init(l);
    v.right_ss.Init(r);
    v.ready = true;
  }
  p->pod_id = pod.id;
  p->fx = pod.stereo.ir.fx;
  p->baseline_m = pod.stereo.baseline_m;
  // The noise depends on the frame and the pod's id only: a pod rendered
  // alone gets the bytes it gets among all pods.
  const uint64_t stream =
      studio::HashOf(options.seed, static_cast<uint64_t>(frame_index), static_cast<uint64_t>(pod.id), 0x1E1EULL);
  studio::RenderViewCore(v.left_ss, tmpl, scene, false, &s);
  ShadeIr(v.left_ss, s, ss, 0.0f, pod, *v.pattern, options, stream, &p->left);
  studio::RenderViewCore(v.right_ss, tmpl, scene, false, &s);
  ShadeIr(v.right_ss, s, ss, static_cast<float>(pod.stereo.baseline_m), pod, *v.pattern, options, stream + 1,
          &p->right);
  studio::RenderViewCore(v.left_truth, tmpl, scene, false, &s);
  const int W = pod.stereo.ir.width, H = pod.stereo.ir.height;
  if (p->disparity.width() != W || p->disparity.height() != H) p->disparity.Resize(W, H);
  const float fb = static_cast<float>(pod.stereo.ir.fx * pod.stereo.baseline_m);
  for (size_t j = 0; j < static_cast<size_t>(W) * H; ++j) {
    const float z = s.out_z[j];
    p->disparity.data()[j] = std::isfinite(z) && z > 0.0f ? fb / z : 0.0f;
  }
  studio::WriteTruth(v.left_truth, s, nullptr, &p->mask);
}

void StereoStudioRenderer::Render(int64_t frame_index, std::vector<StereoPair>* pairs) {
  const Rig& rig = rig_;
  const int num_pods = static_cast<int>(rig.pods.size());
  pairs->resize(num_pods);
  studio_->WithPosedFrame(frame_index, [&](const studio::SceneTemplate& tmpl, const studio::FrameScene& scene,
                                           WorkerPool* pool) {
    if (impl_->scratch.size() < static_cast<size_t>(pool->num_threads())) impl_->scratch.resize(pool->num_threads());
    pool->Run(num_pods, [&](int i, int worker) {
      impl_->RenderPair(rig.pods[i], impl_->pods[i], options_, frame_index, tmpl, scene, impl_->scratch[worker],
                        &(*pairs)[i]);
    });
  });
}

void StereoStudioRenderer::RenderPod(int64_t frame_index, int pod_index, StereoPair* pair) {
  HOLO_CHECK(pod_index >= 0 && pod_index < static_cast<int>(rig_.pods.size()));
  studio_->WithPosedFrame(frame_index, [&](const studio::SceneTemplate& tmpl, const studio::FrameScene& scene,
                                           WorkerPool*) {
    if (impl_->scratch.empty()) impl_->scratch.resize(1);
    impl_->RenderPair(rig_.pods[pod_index], impl_->pods[pod_index], options_, frame_index, tmpl, scene,
                      impl_->scratch[0], pair);
  });
}

}  // namespace holo
