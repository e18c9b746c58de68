#include "protocol/fuzz_video.h"

#include <span>

#include "common/status.h"
#include "protocol/video_codec.h"

namespace holo::protocol {

int FuzzVideoDecoder(const uint8_t* data, size_t size) {
  const std::span<const uint8_t> blob(data, size);
  // Lower limits keep an iteration's memory small; the code paths are the same.
  Limits limits;
  limits.max_image_pixels = 1u << 20;
  int decoded = 0;
  const auto info = ParseVideoBlob(blob, limits);
  auto check = [&](const VideoDecoder& dec) {
    HOLO_CHECK_MSG(info.ok(), "a blob whose header does not parse was decoded");
    HOLO_CHECK(dec.image().width() == static_cast<int>(info->width));
    HOLO_CHECK(dec.image().height() == static_cast<int>(info->height));
    HOLO_CHECK(dec.mask().width() == dec.image().width() && dec.mask().height() == dec.image().height());
    HOLO_CHECK(dec.synced());
    // Every foreground pixel lies in the picture's window.
    const VideoWindow& win = info->window;
    for (int y = 0; y < dec.mask().height(); ++y)
      for (int x = 0; x < dec.mask().width(); ++x) {
        const bool inside = x >= win.x && x < win.x + win.w && y >= win.y && y < win.y + win.h;
        HOLO_CHECK_MSG(inside || dec.mask().at(x, y) == 0, "foreground outside the window was accepted");
      }
    ++decoded;
  };
  VideoDecoder fresh;
  if (fresh.Decode(blob, limits).ok()) {
    HOLO_CHECK_MSG(info->keyframe(), "a fresh decoder decoded a delta frame");
    check(fresh);
  }
  thread_local VideoDecoder stream;
  if (stream.Decode(blob, limits).ok()) check(stream);
  return decoded;
}

}  // namespace holo::protocol
