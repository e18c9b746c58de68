#include "server/capture/prerendered.h"

#include <algorithm>
#include <cstdio>
#include <string>

#include "common/log.h"
#include "studio/studio.h"

namespace holo {

int64_t LoopContent(int64_t k, int64_t n) {
  if (n <= 1 || k < 0) return 0;
  const int64_t period = 2 * (n - 1);
  const int64_t m = k % period;
  return m < n ? m : period - m;
}

PrerenderedSource::PrerenderedSource(const Rig& rig, std::shared_ptr<const std::vector<RgbdFrameSet>> frames, bool loop)
    : rig_(rig), frames_(std::move(frames)), loop_(loop) {}

StatusOr<std::unique_ptr<PrerenderedSource>> PrerenderedSource::Render(SyntheticStudio& studio, int count, bool loop,
                                                                       bool quiet) {
  HOLO_RETURN_IF_ERROR(studio.Seek(0));
  return Record(studio, count, loop, quiet);
}

StatusOr<std::unique_ptr<PrerenderedSource>> PrerenderedSource::Record(FrameSource& source, int count, bool loop,
                                                                       bool quiet) {
  if (count < 1 || count > 3000) return InvalidArgument("prerendered frame count must be in [1, 3000], got " + std::to_string(count));
  auto frames = std::make_shared<std::vector<RgbdFrameSet>>(static_cast<size_t>(count));
  for (int k = 0; k < count; ++k) {
    HOLO_RETURN_IF_ERROR(source.Next(&(*frames)[static_cast<size_t>(k)]).WithContext("pre-rendering frame set " +
                                                                                    std::to_string(k)));
    if (!quiet && ((k + 1) % 10 == 0 || k + 1 == count)) spdlog::info("  pre-rendered {}/{} frame sets", k + 1, count);
  }
  return std::make_unique<PrerenderedSource>(source.rig(), std::move(frames), loop);
}

int64_t PrerenderedSource::ContentFrame(int64_t k) const {
  const int64_t n = static_cast<int64_t>(frames_->size());
  const int64_t i = loop_ ? LoopContent(k, n) : k;
  return (*frames_)[static_cast<size_t>(std::clamp<int64_t>(i, 0, n - 1))].frame_index;
}

Status PrerenderedSource::Next(RgbdFrameSet* out) {
  const int64_t n = static_cast<int64_t>(frames_->size());
  if (n == 0 || (!loop_ && next_ >= n)) return OutOfRange("end of the prerendered frames");
  const int64_t k = next_++;
  const RgbdFrameSet& in = (*frames_)[static_cast<size_t>(loop_ ? LoopContent(k, n) : k)];
  out->frame_index = loop_ ? k : in.frame_index;
  out->frames.resize(in.frames.size());
  // Assignment into a recycled item reuses its buffers once they have the size.
  for (size_t p = 0; p < in.frames.size(); ++p) out->frames[p] = in.frames[p];
  return OkStatus();
}

Status PrerenderedSource::Skip(int64_t n) {
  if (n < 0) return InvalidArgument("cannot skip a negative number of frames");
  if (!loop_ && next_ + n > static_cast<int64_t>(frames_->size())) return OutOfRange("skip past the end");
  next_ += n;
  return OkStatus();
}

Status PrerenderedSource::Seek(int64_t index) {
  if (index < 0 || (!loop_ && index > static_cast<int64_t>(frames_->size()))) return OutOfRange("seek past the end");
  next_ = index;
  return OkStatus();
}

}  // namespace holo
