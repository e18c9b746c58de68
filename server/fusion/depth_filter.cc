#include "server/fusion/depth_filter.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include "common/worker_pool.h"

namespace holo {

Status DepthFilterOptions::Check() const {
  if (radius < 0 || radius > 4) return InvalidArgument("depth filter radius must be in [0, 4], got " + std::to_string(radius));
  if (!(range_sigmas > 0) || !std::isfinite(range_sigmas))
    return InvalidArgument("depth filter range_sigmas must be > 0, got " + std::to_string(range_sigmas));
  if (!(sigma_at_1m_mm > 0) || !std::isfinite(sigma_at_1m_mm))
    return InvalidArgument("depth filter sigma_at_1m_mm must be > 0, got " + std::to_string(sigma_at_1m_mm));
  if (threads < 0) return InvalidArgument("depth filter threads must be >= 0, got " + std::to_string(threads));
  return OkStatus();
}

struct DepthFilter::Scratch {
  std::vector<uint16_t> padded;      // the foreground's bounding box plus `radius`, 0 = not usable
  std::vector<int32_t> center, threshold;
  std::vector<uint32_t> sum, count;
};

StatusOr<std::unique_ptr<DepthFilter>> DepthFilter::Create(DepthFilterOptions options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<DepthFilter> f(new DepthFilter());
  f->options_ = options;
  f->pool_ = std::make_unique<WorkerPool>(ResolveThreadCount(options.threads));
  for (int t = 0; t < f->pool_->num_threads(); ++t) f->scratch_.push_back(std::make_unique<Scratch>());
  return f;
}

DepthFilter::~DepthFilter() = default;

namespace {

Status CheckMask(const ImageDepth16& depth, const ImageGray8& mask, const std::string& what) {
  if (!mask.empty() && (mask.width() != depth.width() || mask.height() != depth.height()))
    return DataLoss(what + ": mask is " + std::to_string(mask.width()) + "x" + std::to_string(mask.height()) +
                    ", depth " + std::to_string(depth.width()) + "x" + std::to_string(depth.height()));
  return OkStatus();
}

}  // namespace

Status DepthFilter::Apply(RgbdFrameSet* frames) {
  for (const RgbdFrame& f : frames->frames)
    HOLO_RETURN_IF_ERROR(CheckMask(f.depth, f.mask, "pod " + std::to_string(f.pod_id)));
  if (options_.radius == 0) return OkStatus();
  pool_->Run(frames->frames.size(), [&](int i, int thread) {
    RgbdFrame& f = frames->frames[static_cast<size_t>(i)];
    FilterOne(&f.depth, f.mask, scratch_[static_cast<size_t>(thread)].get());
  });
  return OkStatus();
}

Status DepthFilter::Apply(ImageDepth16* depth, const ImageGray8& mask) {
  HOLO_RETURN_IF_ERROR(CheckMask(*depth, mask, "depth filter"));
  if (options_.radius > 0) FilterOne(depth, mask, scratch_[0].get());
  return OkStatus();
}

void DepthFilter::FilterOne(ImageDepth16* depth, const ImageGray8& mask, Scratch* s) const {
  const int w = depth->width(), h = depth->height(), r = options_.radius;
  const bool masked = !mask.empty();
  auto usable = [&](int x, int y) { return depth->at(x, y) != 0 && (!masked || mask.at(x, y) != 0); };
  // Bounding box of the usable pixels: outside it nothing is filtered and
  // nothing contributes.
  int x0 = w, x1 = -1, y0 = h, y1 = -1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (usable(x, y)) {
        x0 = std::min(x0, x);
        x1 = std::max(x1, x);
        y0 = std::min(y0, y);
        y1 = std::max(y1, y);
      }
  if (x1 < 0) return;
  const int bw = x1 - x0 + 1, bh = y1 - y0 + 1;
  const int pw = bw + 2 * r;
  s->padded.assign(static_cast<size_t>(pw) * (bh + 2 * r), 0);
  for (int y = y0; y <= y1; ++y) {
    uint16_t* row = s->padded.data() + static_cast<size_t>(y - y0 + r) * pw + r;
    for (int x = x0; x <= x1; ++x) row[x - x0] = usable(x, y) ? depth->at(x, y) : 0;
  }
  s->center.resize(static_cast<size_t>(bw));
  s->threshold.resize(static_cast<size_t>(bw));
  s->sum.resize(static_cast<size_t>(bw));
  s->count.resize(static_cast<size_t>(bw));
  // σ(z) in mm for z in mm: sigma_at_1m_mm · (z / 1000)².
  const float k = options_.range_sigmas * options_.sigma_at_1m_mm * 1e-6f;
  int32_t* center = s->center.data();
  int32_t* thr = s->threshold.data();
  uint32_t* sum = s->sum.data();
  uint32_t* cnt = s->count.data();
  for (int y = 0; y < bh; ++y) {
    const uint16_t* mid = s->padded.data() + static_cast<size_t>(y + r) * pw + r;
    for (int x = 0; x < bw; ++x) {
      const int32_t d = mid[x];
      center[x] = d;
      // The threshold stays below the centre's depth, so an unusable
      // neighbour (0) never passes the range test.
      const float t = k * static_cast<float>(d) * static_cast<float>(d);
      thr[x] = d == 0 ? 0 : std::min(static_cast<int32_t>(t), d - 1);
      sum[x] = 0;
      cnt[x] = 0;
    }
    for (int dy = -r; dy <= r; ++dy) {
      const uint16_t* src = s->padded.data() + static_cast<size_t>(y + r + dy) * pw + r;
      for (int dx = -r; dx <= r; ++dx) {
        const uint16_t* q = src + dx;
        // |e − d| ≤ t as one unsigned compare: (e − d + t) ∈ [0, 2t].
        for (int x = 0; x < bw; ++x) {
          const int32_t e = q[x];
          const uint32_t ok = static_cast<uint32_t>(e - center[x] + thr[x]) <= static_cast<uint32_t>(2 * thr[x]);
          sum[x] += ok ? static_cast<uint32_t>(e) : 0u;
          cnt[x] += ok;
        }
      }
    }
    uint16_t* out = depth->row(y0 + y) + x0;
    for (int x = 0; x < bw; ++x)
      if (center[x] != 0) out[x] = static_cast<uint16_t>((sum[x] + cnt[x] / 2) / cnt[x]);
  }
}

}  // namespace holo
