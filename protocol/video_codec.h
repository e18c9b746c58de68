// Video colour (V1, colour codec id 4, PROTOCOL.md §8): each pod's foreground
// colour as one low-latency inter-frame video stream, through libavcodec.
//
// One VideoEncoder and one VideoDecoder per pod stream. Every blob is one
// frame: the encoder emits exactly one coded picture per input image (zero
// latency, no B-frames, no lookahead, one thread), the decoder returns that
// picture at once. A blob is either a keyframe (decodes alone) or a delta
// frame (needs the previous frame of the same stream). The mask of the whole
// image travels losslessly in every blob (coded blocks through a binary range
// coder, or C1's row-transition coding with zstd), so the mask never depends
// on earlier blobs. The picture covers only a window around the foreground
// (the encoder picks and moves it; PROTOCOL.md §8).
//
// Background pixels carry no information; the encoder fills them so they cost
// almost nothing and stay stable from frame to frame: every 16×16 block
// without foreground is one flat grey (identical in every frame, so it is
// skipped), and inside a block with foreground the background continues the
// foreground (repetitive padding along rows, then columns, as C1 does) so the
// block holds no artificial edge.
//
// Libraries (all through libavcodec as Debian builds it):
//   kH264 — libx264 encoder (High 4:4:4 Predictive or High), FFmpeg's h264
//           decoder. The default: fastest on one core at the best PSNR per bit
//           measured (docs/codecs.md).
//   kVp9  — libvpx-vp9 encoder (profile 1 for 4:4:4) and decoder.
// Library id 3 is reserved for AV1: Debian 12's SVT-AV1 1.4 through
// libavcodec 5.1 held frames back (no picture out per picture in, even with
// the low-delay structure and no lookahead), so it is not zero-latency here.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/image.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::protocol {

// The ColorFrame codec id of V1 (ColorCodec in messages.h has no name for it
// yet; the wiring adds `kV1 = 4`).
inline constexpr uint8_t kColorCodecVideo = 4;

// Colour-blob flags of V1 (the byte after the codec id).
inline constexpr uint8_t kVideoFlagKeyframe = 1;  // decodes without earlier blobs
inline constexpr uint8_t kVideoFlagChroma444 = 2; // the picture is 4:4:4 (else 4:2:0)
inline constexpr uint8_t kVideoFlagMaskBlocks = 4; // the mask is coded blocks (else zstd rows)
inline constexpr uint8_t kVideoFlagWindow = 8;     // the picture is a window of the image (else all of it)

// The part of a pod's image that the coded picture holds (pixels; even width
// and height, inside the image). Every foreground pixel lies inside it.
struct VideoWindow {
  int x = 0, y = 0, w = 0, h = 0;
  bool operator==(const VideoWindow&) const = default;
};

enum class VideoLibrary : uint8_t { kH264 = 1, kVp9 = 2 };

// "x264", "vpx-vp9"; "?" for other values.
const char* VideoLibraryName(VideoLibrary library);

struct VideoEncodeOptions {
  VideoLibrary library = VideoLibrary::kH264;
  // 4:4:4 (true) or 4:2:0 chroma. The studio's saturated stripes and checks
  // lose most to 4:2:0 chroma (docs/codecs.md).
  bool chroma_444 = true;
  // Constant-quality factor: x264 CRF 0..51, VP9 CRF 0..63; -1 = the
  // library's default here (x264 24, VP9 32). x264 CRF 24 (4:4:4, ultrafast,
  // tuned for PSNR) kept the S8-QVGA studio at 34.8 dB foreground PSNR in
  // 61 % of C1's bytes (docs/codecs.md).
  int crf = -1;
  // Encoder speed preset: x264 "ultrafast".."placebo", VP9 cpu-used 5..9
  // as a number. Empty = the default here: x264 "veryfast" (on fused S8-VGA
  // pods it codes 40 % fewer bytes than "ultrafast" at the same foreground
  // PSNR for 1.3x the encode CPU and the same decode CPU, docs/codecs.md),
  // VP9 "8".
  std::string preset;
  // A keyframe at least every `keyframe_interval` frames (1..1000): a new
  // viewer, a recorder's seek or a viewer after loss decodes again within
  // this many frames (2 s at 30 fps by default). RequestKeyframe() forces one
  // sooner.
  int keyframe_interval = 60;
  // The mask as coded blocks: 16×16 block types, then the mixed blocks'
  // pixels through an adaptive binary range coder (about half the bytes of
  // the zstd row format on the site's masks; PROTOCOL.md §8). false: rows.
  bool mask_blocks = true;
  // Code only a window around the foreground (flag bit 3), not the whole
  // image: the library's cost follows the picture's pixels, and a pod sees
  // the person in a fraction of its image. The window keeps its size from
  // keyframe to keyframe and moves in 16-pixel steps to follow the
  // foreground; it is chosen with room to spare, and a foreground that
  // outgrows it starts a keyframe with a larger window. false: the picture
  // is the whole image.
  bool window = true;
  Status Check() const;
};

// Encodes one pod's images, frame after frame, into V1 blobs. Not thread-safe:
// one encoder per stream. The image size is fixed by the first image; a
// different size later is InvalidArgument (make a new encoder).
class VideoEncoder {
 public:
  // InvalidArgument on bad options; Unavailable when libavcodec lacks the
  // library's encoder. Opening the library waits for the first image.
  static StatusOr<std::unique_ptr<VideoEncoder>> Create(const VideoEncodeOptions& options);
  ~VideoEncoder();
  VideoEncoder(const VideoEncoder&) = delete;
  VideoEncoder& operator=(const VideoEncoder&) = delete;

  // Encodes `image` with foreground `mask` (same size, 0 = background; empty
  // = all foreground) and appends one blob to `out`. Width and height must be
  // even (4:2:0) and ≤ 8192. InvalidArgument on sizes; Internal if the
  // library fails (the encoder then restarts with a keyframe).
  Status Encode(const ImageRgb8& image, const ImageGray8& mask, std::vector<uint8_t>* out);
  // The next Encode emits a keyframe (e.g. a viewer lost a frame, or joined).
  void RequestKeyframe() { keyframe_requested_ = true; }
  const VideoEncodeOptions& options() const { return options_; }
  int64_t frames() const { return frame_number_; }
  int64_t keyframes() const { return keyframes_; }
  // The window of the last blob (the whole image with `window` off).
  const VideoWindow& window() const { return window_; }
  // Keyframes that a new window size forced (a foreground that outgrew the
  // window between two keyframes).
  int64_t window_resizes() const { return window_resizes_; }

 private:
  struct Impl;
  explicit VideoEncoder(const VideoEncodeOptions& options);
  VideoEncodeOptions options_;
  std::unique_ptr<Impl> impl_;
  bool keyframe_requested_ = false;
  uint32_t frame_number_ = 0;
  int64_t keyframes_ = 0;
  int64_t since_keyframe_ = 0;
  VideoWindow window_;
  int64_t window_resizes_ = 0;
};

// Decodes one pod's V1 blobs into images it keeps. Safe on untrusted input:
// every field is checked before use, the picture size is checked against
// `limits` before the library sees the bitstream, and a picture whose size
// or format differs from the blob's header is refused. Not thread-safe: one
// decoder per stream.
//
// A delta frame decodes only right after the previous frame of its stream
// (frame number + 1, same image and picture size, library and chroma; the
// window may move). Otherwise Decode returns
// Unavailable ("waiting for a keyframe ...") and keeps refusing delta frames
// until a keyframe arrives: the receiver should ask the sender for one
// (Control) and show the last picture meanwhile. After DataLoss (a malformed
// blob) the decoder likewise waits for a keyframe.
class VideoDecoder {
 public:
  VideoDecoder();
  ~VideoDecoder();
  VideoDecoder(const VideoDecoder&) = delete;
  VideoDecoder& operator=(const VideoDecoder&) = delete;

  // Decodes one blob; on success image() (background 0) and mask() (255 =
  // foreground) hold the frame. DataLoss naming the field on malformed bytes;
  // Unavailable when a keyframe is needed; UnsupportedVersion for an unknown
  // library; Unavailable when libavcodec lacks the library's decoder.
  Status Decode(std::span<const uint8_t> blob, const Limits& limits = {});
  const ImageRgb8& image() const { return image_; }
  const ImageGray8& mask() const { return mask_; }
  // True when the next delta frame of the stream can be decoded.
  bool synced() const { return synced_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  ImageRgb8 image_;
  ImageGray8 mask_;
  bool synced_ = false;
};

// The fields of a V1 blob's header, for tools and tests. Safe on untrusted
// input (checks only the header; DataLoss naming the field).
struct VideoBlobInfo {
  uint8_t flags = 0;
  uint32_t width = 0, height = 0;
  VideoLibrary library = VideoLibrary::kH264;
  uint32_t frame_number = 0;
  size_t mask_bytes = 0, video_bytes = 0;
  size_t mask_offset = 0, video_offset = 0;  // where the two byte ranges start in the blob
  VideoWindow window;  // the whole image when flag bit 3 is clear
  bool keyframe() const { return (flags & kVideoFlagKeyframe) != 0; }
};
StatusOr<VideoBlobInfo> ParseVideoBlob(std::span<const uint8_t> blob, const Limits& limits = {});

}  // namespace holo::protocol
