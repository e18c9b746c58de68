#include "server/stereo/sgbm.h"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace holo {

struct SgbmStereo::Impl {
  int min_d = 0;
  cv::Ptr<cv::StereoSGBM> sgbm;
  cv::Mat left, right, disp;  // the padded pair and its disparity
};

SgbmStereo::SgbmStereo(float min_d, float max_d) : impl_(std::make_unique<Impl>()) {
  impl_->min_d = std::max(0, static_cast<int>(std::floor(min_d)));
  const int num = std::max(16, static_cast<int>(std::ceil((max_d - static_cast<float>(impl_->min_d)) / 16.0f)) * 16);
  const int bs = 5;
  impl_->sgbm = cv::StereoSGBM::create(impl_->min_d, num, bs, 8 * bs * bs, 32 * bs * bs, 1, 0, 10, 100, 2,
                                       cv::StereoSGBM::MODE_SGBM_3WAY);
}

SgbmStereo::~SgbmStereo() = default;

void SgbmStereo::Compute(const ImageGray8& l, const ImageGray8& r, ImageFloat* out) {
  if (l.width() != r.width() || l.height() != r.height() || l.width() == 0 || l.height() == 0) {
    out->Resize(0, 0);
    return;
  }
  const cv::Mat lm(l.height(), l.width(), CV_8UC1, const_cast<uint8_t*>(l.data()));
  const cv::Mat rm(r.height(), r.width(), CV_8UC1, const_cast<uint8_t*>(r.data()));
  // SGBM gives no disparity in the left image's first min + range columns
  // (it takes only matches that stay inside the right image over the whole
  // range), where pixels with a smaller disparity do have a match: a person
  // entering from the left would go unseen there. Both images get that many
  // black columns on the left, cropped from the result.
  const int pad = impl_->min_d + impl_->sgbm->getNumDisparities();
  cv::copyMakeBorder(lm, impl_->left, 0, 0, pad, 0, cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::copyMakeBorder(rm, impl_->right, 0, 0, pad, 0, cv::BORDER_CONSTANT, cv::Scalar(0));
  impl_->sgbm->compute(impl_->left, impl_->right, impl_->disp);
  out->Resize(l.width(), l.height());
  const int lo = impl_->min_d * 16;
  for (int y = 0; y < l.height(); ++y) {
    const int16_t* s = impl_->disp.ptr<int16_t>(y) + pad;
    float* o = out->row(y);
    for (int x = 0; x < l.width(); ++x) o[x] = s[x] < lo ? 0.0f : std::max(0.0f, static_cast<float>(s[x]) / 16.0f);
  }
}

}  // namespace holo
