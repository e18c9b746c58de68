#include "server/segment/mog2_baseline.h"

#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/video/background_segm.hpp>

namespace holo {

Status Mog2Options::Check() const {
  if (history < 1) return InvalidArgument("history must be >= 1, got " + std::to_string(history));
  if (!(var_threshold > 0)) return InvalidArgument("var_threshold must be > 0, got " + std::to_string(var_threshold));
  return OkStatus();
}

struct Mog2Segmenter::Impl {
  Mog2Options options;
  std::vector<cv::Ptr<cv::BackgroundSubtractorMOG2>> models;
  std::vector<cv::Mat> fg;
  int width = -1, height = -1;
  bool trained = false;
};

Mog2Segmenter::Mog2Segmenter(int num_pods, Mog2Options options) : impl_(std::make_unique<Impl>()) {
  const Status st = options.Check();
  HOLO_CHECK_MSG(st.ok(), st.ToString());
  HOLO_CHECK(num_pods > 0);
  impl_->options = options;
  for (int i = 0; i < num_pods; ++i)
    impl_->models.push_back(
        cv::createBackgroundSubtractorMOG2(options.history, options.var_threshold, options.detect_shadows));
  impl_->fg.resize(static_cast<size_t>(num_pods));
}

Mog2Segmenter::~Mog2Segmenter() = default;

namespace {
Status CheckSet(const RgbdFrameSet& frames, size_t pods, const char* what) {
  if (frames.frames.size() != pods)
    return InvalidArgument(std::string(what) + ": frame set has " + std::to_string(frames.frames.size()) +
                           " pods, expected " + std::to_string(pods));
  return OkStatus();
}
// A borrowed cv::Mat header on our RGB image (MOG2 does not care about the
// channel order as long as it is the same in training and test).
cv::Mat Wrap(const ImageRgb8& img) {
  return cv::Mat(img.height(), img.width(), CV_8UC3, const_cast<uint8_t*>(img.data()));
}
}  // namespace

Status Mog2Segmenter::AddBackgroundFrame(const RgbdFrameSet& frames) {
  HOLO_RETURN_IF_ERROR(CheckSet(frames, impl_->models.size(), "Mog2Segmenter::AddBackgroundFrame"));
  for (size_t i = 0; i < impl_->models.size(); ++i) {
    const ImageRgb8& c = frames.frames[i].color;
    if (c.empty()) return InvalidArgument("Mog2Segmenter: pod " + std::to_string(i) + " has no colour image");
    if (impl_->trained && (c.width() != impl_->width || c.height() != impl_->height))
      return InvalidArgument("Mog2Segmenter: pod " + std::to_string(i) + " colour size changed");
    impl_->width = c.width(), impl_->height = c.height();
    impl_->models[i]->apply(Wrap(c), impl_->fg[i], -1.0);
  }
  impl_->trained = true;
  return OkStatus();
}

Status Mog2Segmenter::Segment(RgbdFrameSet* frames) {
  if (!impl_->trained) return InvalidArgument("Mog2Segmenter::Segment: no background frame was added");
  HOLO_RETURN_IF_ERROR(CheckSet(*frames, impl_->models.size(), "Mog2Segmenter::Segment"));
  for (size_t i = 0; i < impl_->models.size(); ++i) {
    RgbdFrame& f = frames->frames[i];
    if (f.color.width() != impl_->width || f.color.height() != impl_->height)
      return InvalidArgument("Mog2Segmenter::Segment: pod " + std::to_string(i) + " colour size differs from training");
    impl_->models[i]->apply(Wrap(f.color), impl_->fg[i], 0.0);
    f.mask.Resize(f.color.width(), f.color.height());
    const cv::Mat& m = impl_->fg[i];
    for (int y = 0; y < m.rows; ++y) {
      const uint8_t* src = m.ptr<uint8_t>(y);
      uint8_t* dst = f.mask.row(y);
      for (int x = 0; x < m.cols; ++x) dst[x] = src[x] == 255 ? 255 : 0;  // 127 = shadow → background
    }
  }
  return OkStatus();
}

}  // namespace holo
