#include "common/metrics/image_metrics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace holo::metrics {
namespace {

std::string SizeOf(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

template <typename A, typename B>
Status CheckSameSize(const A& a, const B& b, const char* what_a, const char* what_b) {
  if (a.empty() || b.empty())
    return InvalidArgument(std::string(a.empty() ? what_a : what_b) + " image is empty");
  if (a.width() != b.width() || a.height() != b.height())
    return InvalidArgument(std::string(what_a) + " is " + SizeOf(a.width(), a.height()) + " but " + what_b + " is " +
                           SizeOf(b.width(), b.height()));
  return OkStatus();
}

template <typename ImageT>
Status CheckInputs(const ImageT& a, const ImageT& b, const ImageGray8* mask) {
  HOLO_RETURN_IF_ERROR(CheckSameSize(a, b, "first image", "second image"));
  if (mask != nullptr) HOLO_RETURN_IF_ERROR(CheckSameSize(a, *mask, "image", "mask"));
  return OkStatus();
}

template <typename ImageT>
StatusOr<double> Psnr(const ImageT& a, const ImageT& b, const ImageGray8* mask) {
  HOLO_RETURN_IF_ERROR(CheckInputs(a, b, mask));
  constexpr int C = ImageT::kChannels;
  uint64_t sum_sq = 0, count = 0;
  const size_t n = a.num_pixels();
  const uint8_t* pa = a.data();
  const uint8_t* pb = b.data();
  for (size_t i = 0; i < n; ++i) {
    if (mask != nullptr && mask->data()[i] == 0) continue;
    for (int c = 0; c < C; ++c) {
      const int d = static_cast<int>(pa[i * C + c]) - static_cast<int>(pb[i * C + c]);
      sum_sq += static_cast<uint64_t>(d * d);
    }
    count += C;
  }
  if (count == 0) return InvalidArgument("PSNR: the mask selects no pixel");
  const double mse = static_cast<double>(sum_sq) / static_cast<double>(count);
  if (mse <= 255.0 * 255.0 * 1e-10) return kPsnrCapDb;
  return std::min(kPsnrCapDb, 10.0 * std::log10(255.0 * 255.0 / mse));
}

constexpr int kSsimWindow = 11;
constexpr int kSsimRadius = kSsimWindow / 2;

std::array<double, kSsimWindow> GaussianKernel() {
  std::array<double, kSsimWindow> k{};
  double sum = 0;
  for (int i = 0; i < kSsimWindow; ++i) {
    const double x = i - kSsimRadius;
    k[i] = std::exp(-x * x / (2 * 1.5 * 1.5));
    sum += k[i];
  }
  for (double& v : k) v /= sum;
  return k;
}

// One channel as doubles, row-major.
struct Plane {
  int width = 0, height = 0;
  std::vector<double> v;
};

// Gaussian-weighted local means of `in` over the valid region: output is
// (width − 10) × (height − 10), output (x, y) is centred on input (x+5, y+5).
std::vector<double> FilterValid(const std::vector<double>& in, int width, int height) {
  static const std::array<double, kSsimWindow> k = GaussianKernel();
  const int ow = width - 2 * kSsimRadius, oh = height - 2 * kSsimRadius;
  std::vector<double> horiz(static_cast<size_t>(ow) * height);
  for (int y = 0; y < height; ++y) {
    const double* row = in.data() + static_cast<size_t>(y) * width;
    double* out = horiz.data() + static_cast<size_t>(y) * ow;
    for (int x = 0; x < ow; ++x) {
      double s = 0;
      for (int i = 0; i < kSsimWindow; ++i) s += k[i] * row[x + i];
      out[x] = s;
    }
  }
  std::vector<double> out(static_cast<size_t>(ow) * oh, 0.0);
  for (int y = 0; y < oh; ++y) {
    double* o = out.data() + static_cast<size_t>(y) * ow;
    for (int i = 0; i < kSsimWindow; ++i) {
      const double* h = horiz.data() + static_cast<size_t>(y + i) * ow;
      for (int x = 0; x < ow; ++x) o[x] += k[i] * h[x];
    }
  }
  return out;
}

// Mean SSIM of two planes over valid-region pixels inside `mask`.
StatusOr<double> SsimPlane(const Plane& a, const Plane& b, const ImageGray8* mask) {
  const int w = a.width, h = a.height;
  std::vector<double> aa(a.v.size()), bb(a.v.size()), ab(a.v.size());
  for (size_t i = 0; i < a.v.size(); ++i) {
    aa[i] = a.v[i] * a.v[i];
    bb[i] = b.v[i] * b.v[i];
    ab[i] = a.v[i] * b.v[i];
  }
  const std::vector<double> mu_a = FilterValid(a.v, w, h), mu_b = FilterValid(b.v, w, h);
  const std::vector<double> e_aa = FilterValid(aa, w, h), e_bb = FilterValid(bb, w, h), e_ab = FilterValid(ab, w, h);
  constexpr double kC1 = (0.01 * 255) * (0.01 * 255), kC2 = (0.03 * 255) * (0.03 * 255);
  const int ow = w - 2 * kSsimRadius, oh = h - 2 * kSsimRadius;
  double sum = 0;
  size_t count = 0;
  for (int y = 0; y < oh; ++y) {
    for (int x = 0; x < ow; ++x) {
      if (mask != nullptr && mask->at(x + kSsimRadius, y + kSsimRadius) == 0) continue;
      const size_t i = static_cast<size_t>(y) * ow + x;
      const double ma = mu_a[i], mb = mu_b[i];
      const double va = e_aa[i] - ma * ma, vb = e_bb[i] - mb * mb, cov = e_ab[i] - ma * mb;
      sum += ((2 * ma * mb + kC1) * (2 * cov + kC2)) / ((ma * ma + mb * mb + kC1) * (va + vb + kC2));
      ++count;
    }
  }
  if (count == 0)
    return InvalidArgument("SSIM: the mask selects no pixel at least 5 pixels from the image border");
  return sum / static_cast<double>(count);
}

template <typename ImageT>
Plane ExtractPlane(const ImageT& img, int channel) {
  Plane p{img.width(), img.height(), std::vector<double>(img.num_pixels())};
  for (size_t i = 0; i < img.num_pixels(); ++i) p.v[i] = img.data()[i * ImageT::kChannels + channel];
  return p;
}

Plane LumaPlane(const ImageRgb8& img) {
  Plane p{img.width(), img.height(), std::vector<double>(img.num_pixels())};
  const uint8_t* d = img.data();
  for (size_t i = 0; i < img.num_pixels(); ++i) p.v[i] = 0.299 * d[3 * i] + 0.587 * d[3 * i + 1] + 0.114 * d[3 * i + 2];
  return p;
}

template <typename ImageT>
Status CheckSsimInputs(const ImageT& a, const ImageT& b, const ImageGray8* mask) {
  HOLO_RETURN_IF_ERROR(CheckInputs(a, b, mask));
  if (a.width() < kSsimWindow || a.height() < kSsimWindow)
    return InvalidArgument("SSIM needs images of at least 11x11, got " + SizeOf(a.width(), a.height()));
  return OkStatus();
}

}  // namespace

StatusOr<double> ComputePsnr(const ImageRgb8& a, const ImageRgb8& b, const ImageGray8* mask) {
  return Psnr(a, b, mask);
}
StatusOr<double> ComputePsnr(const ImageGray8& a, const ImageGray8& b, const ImageGray8* mask) {
  return Psnr(a, b, mask);
}

StatusOr<double> ComputeSsim(const ImageRgb8& a, const ImageRgb8& b, const ImageGray8* mask,
                             const SsimOptions& options) {
  HOLO_RETURN_IF_ERROR(CheckSsimInputs(a, b, mask));
  if (options.channels == SsimChannels::kLuma) return SsimPlane(LumaPlane(a), LumaPlane(b), mask);
  double sum = 0;
  for (int c = 0; c < 3; ++c) {
    HOLO_ASSIGN_OR_RETURN(const double s, SsimPlane(ExtractPlane(a, c), ExtractPlane(b, c), mask));
    sum += s;
  }
  return sum / 3;
}

StatusOr<double> ComputeSsim(const ImageGray8& a, const ImageGray8& b, const ImageGray8* mask) {
  HOLO_RETURN_IF_ERROR(CheckSsimInputs(a, b, mask));
  return SsimPlane(ExtractPlane(a, 0), ExtractPlane(b, 0), mask);
}

StatusOr<DepthErrorStats> ComputeDepthError(const ImageDepth16& estimate, const ImageDepth16& truth,
                                            const ImageGray8* mask) {
  HOLO_RETURN_IF_ERROR(CheckSameSize(estimate, truth, "estimate", "truth"));
  if (mask != nullptr) HOLO_RETURN_IF_ERROR(CheckSameSize(truth, *mask, "truth", "mask"));
  DepthErrorStats s;
  double sum_abs = 0, sum_sq = 0, sum_signed = 0;
  std::vector<uint16_t> abs_errors;
  for (size_t i = 0; i < truth.num_pixels(); ++i) {
    if (mask != nullptr && mask->data()[i] == 0) continue;
    const int t = truth.data()[i], e = estimate.data()[i];
    if (t == 0) continue;
    ++s.num_truth_valid;
    if (e == 0) continue;
    const int d = e - t;
    sum_signed += d;
    sum_abs += std::abs(d);
    sum_sq += static_cast<double>(d) * d;
    abs_errors.push_back(static_cast<uint16_t>(std::abs(d)));
  }
  if (s.num_truth_valid == 0) return InvalidArgument("depth error: no valid truth pixel inside the mask");
  s.num_compared = abs_errors.size();
  s.fraction_valid = static_cast<double>(s.num_compared) / static_cast<double>(s.num_truth_valid);
  if (s.num_compared == 0) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    s.mean_abs_error_mm = s.rmse_mm = s.mean_signed_error_mm = s.median_abs_error_mm = nan;
    return s;
  }
  const double n = static_cast<double>(s.num_compared);
  s.mean_abs_error_mm = sum_abs / n;
  s.rmse_mm = std::sqrt(sum_sq / n);
  s.mean_signed_error_mm = sum_signed / n;
  // Lower median for an even count, so it is always an observed value.
  const size_t k = (abs_errors.size() - 1) / 2;
  std::nth_element(abs_errors.begin(), abs_errors.begin() + static_cast<std::ptrdiff_t>(k), abs_errors.end());
  s.median_abs_error_mm = abs_errors[k];
  return s;
}

StatusOr<MaskOverlap> CompareMasks(const ImageGray8& predicted, const ImageGray8& truth) {
  HOLO_RETURN_IF_ERROR(CheckSameSize(predicted, truth, "predicted mask", "truth mask"));
  MaskOverlap m;
  for (size_t i = 0; i < truth.num_pixels(); ++i) {
    const bool p = predicted.data()[i] != 0, t = truth.data()[i] != 0;
    m.predicted_count += p;
    m.truth_count += t;
    m.intersection += p && t;
    m.union_count += p || t;
  }
  // 0/0 means perfect agreement only when both masks are empty.
  const bool both_empty = m.union_count == 0;
  auto ratio = [&](size_t num, size_t den) {
    if (den == 0) return both_empty ? 1.0 : 0.0;
    return static_cast<double>(num) / static_cast<double>(den);
  };
  m.iou = ratio(m.intersection, m.union_count);
  m.precision = ratio(m.intersection, m.predicted_count);
  m.recall = ratio(m.intersection, m.truth_count);
  return m;
}

}  // namespace holo::metrics
