// Voice frames and their codecs: 20 ms of 48 kHz mono speech, Opus (VoIP mode,
// in-band FEC) or the 16-bit PCM baseline, carried in the protocol's AudioPose
// payload (protocol/PROTOCOL.md, message 7) together with the speaker's head pose.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/status.h"
#include "protocol/messages.h"

struct OpusEncoder;
struct OpusDecoder;

namespace holo::audio {

using protocol::AudioCodec;
using protocol::AudioPose;
using protocol::HeadPose;

inline constexpr int kSampleRate = 48000;
inline constexpr int kFrameSamples = 960;        // 20 ms at 48 kHz
inline constexpr int64_t kFrameUs = 20000;
// Largest Opus packet we produce or accept (RFC 6716 allows 1275 per frame).
inline constexpr int kMaxOpusPacket = 1275;

// How much later a decoded sample comes out than it went in, samples at
// 48 kHz: libopus's look-ahead for the VoIP and audio applications (2.5 ms
// + 4 ms delay compensation = 312 samples, OPUS_GET_LOOKAHEAD); 0 for PCM.
// Lip sync adds it to the voice's playout delay.
int CodecDelaySamples(AudioCodec codec);

// A sender of 20 ms frames after a stall (a loaded machine did not run its
// thread): when the next frame's capture time `*next_us` is more than
// `max_behind_us` behind `now_us`, moves it forward by the whole frames it is
// behind and `*sequence` by as many, so that no burst of stale frames goes
// out and the receivers count the frames not made as lost (capture times and
// sequence numbers stay in step for their jitter buffers). Returns the frames
// skipped (0: not that far behind).
int64_t SkipStalledFrames(int64_t now_us, int64_t max_behind_us, int64_t* next_us, uint32_t* sequence);

// True for the codecs whose audio bytes are Opus packets (classic and lean
// AudioPose layouts); one VoiceDecoder plays both.
bool IsOpus(AudioCodec codec);

// Opus rate control (OPUS_SET_VBR / OPUS_SET_VBR_CONSTRAINT).
enum class OpusRateControl : uint8_t { kVbr, kConstrainedVbr, kCbr };

struct VoiceEncoderOptions {
  // kOpusLean: the same Opus packets in the lean AudioPose layout (PROTOCOL.md
  // §9.1); EncodeFrame quantizes the pose as a receiver will see it.
  AudioCodec codec = AudioCodec::kOpus;
  // Opus target bitrate, bit/s (6000..510000). Ignored for PCM. The lean
  // default (LeanVoiceEncoderOptions) is lower: docs/audio.md "Lean frames".
  int bitrate_bps = 24000;
  // OPUS_APPLICATION_VOIP (true) or OPUS_APPLICATION_AUDIO; both have the same
  // look-ahead (312 samples).
  bool voip_application = true;
  // libopus's default, constrained VBR (unconstrained gives the same packets
  // for speech at ≤ 24 kbit/s: SILK ignores the constraint; docs/audio.md).
  OpusRateControl rate_control = OpusRateControl::kConstrainedVbr;
  // OPUS_SET_MAX_BANDWIDTH: 0 = libopus decides, else 8000 (narrowband),
  // 12000, 16000 (wideband), 24000 (super-wideband), 48000 (fullband): the
  // audio bandwidth in Hz × 2.
  int max_bandwidth_hz = 0;
  // Lean layout only: the head pose goes in every `pose_every`-th frame (1 or
  // 2; frames whose sequence is a multiple of it); the receiver's jitter
  // buffer interpolates the others.
  int pose_every = 1;
  // Opus in-band forward error correction (the previous frame at lower quality).
  bool fec = true;
  // Loss the encoder plans FEC for, percent (0..100).
  int expected_loss_pct = 10;
  // Opus complexity 0..10.
  int complexity = 9;
  Status Check() const;
};

// The lean frame's settings, chosen by measurement (docs/audio.md "Lean
// frames"): codec kOpusLean, Opus at the stated bitrate, the rest as above.
VoiceEncoderOptions LeanVoiceEncoderOptions();

// Encodes 20 ms frames. Not thread-safe; copies are deleted.
class VoiceEncoder {
 public:
  // InvalidArgument for bad options, Internal if libopus refuses them.
  static StatusOr<std::unique_ptr<VoiceEncoder>> Create(const VoiceEncoderOptions& options);
  ~VoiceEncoder();
  VoiceEncoder(const VoiceEncoder&) = delete;
  VoiceEncoder& operator=(const VoiceEncoder&) = delete;

  // Encodes exactly kFrameSamples mono samples in [-1, 1] into the audio bytes
  // of one AudioPose (an Opus packet, or s16le PCM).
  StatusOr<std::vector<uint8_t>> Encode(std::span<const float> pcm);
  // Builds a complete frame: codec fields, `sequence`, `capture_time_us`, `pose`.
  StatusOr<AudioPose> EncodeFrame(std::span<const float> pcm, uint32_t sequence, int64_t capture_time_us,
                                  const HeadPose& pose);
  const VoiceEncoderOptions& options() const { return options_; }
  // The encoder's look-ahead, samples (OPUS_GET_LOOKAHEAD; 0 for PCM).
  int lookahead_samples() const;

 private:
  VoiceEncoder() = default;
  VoiceEncoderOptions options_;
  OpusEncoder* enc_ = nullptr;
};

// Decodes frames of one speaker, in order; conceals lost ones. Not thread-safe.
class VoiceDecoder {
 public:
  static StatusOr<std::unique_ptr<VoiceDecoder>> Create(AudioCodec codec);
  ~VoiceDecoder();
  VoiceDecoder(const VoiceDecoder&) = delete;
  VoiceDecoder& operator=(const VoiceDecoder&) = delete;

  // Decodes the audio bytes of one validated frame into kFrameSamples samples.
  // DataLoss if the bytes do not decode to exactly 20 ms.
  StatusOr<std::vector<float>> Decode(std::span<const uint8_t> audio);
  // 20 ms for a lost frame: recovered from the FEC data in `next_packet` (the
  // frame after the lost one) when given (libopus conceals by itself if that
  // packet has no FEC data), else Opus packet-loss concealment; zeros for PCM.
  // `*used_fec` is true when the FEC path was taken.
  std::vector<float> Conceal(std::span<const uint8_t> next_packet, bool* used_fec);
  AudioCodec codec() const { return codec_; }

 private:
  VoiceDecoder() = default;
  AudioCodec codec_ = AudioCodec::kOpus;
  OpusDecoder* dec_ = nullptr;
};

// Checks what the audio path needs beyond the protocol's own checks: 48 kHz,
// mono, 20 ms, PCM of exactly 1920 bytes, an Opus packet that decodes to
// exactly 960 samples, a head pose within 1 km and ±2π. Returns DataLoss with
// the reason. Safe on untrusted input.
Status ValidateVoiceFrame(const AudioPose& frame);

// Decodes an AudioPose payload (the bytes after the protocol header) and
// validates it for the audio path. Safe on untrusted input. A lean frame
// (codec 3) takes its sequence and capture time from `header`; the overload
// without a header refuses lean frames (DataLoss naming the reason).
StatusOr<AudioPose> ParseVoiceFrame(const protocol::Header& header, std::span<const uint8_t> payload);
StatusOr<AudioPose> ParseVoiceFrame(std::span<const uint8_t> payload);
// The payload bytes of `frame` (protocol::EncodePayload). For a lean frame
// the message header must carry its sequence and capture time
// (protocol::BindHeaderToPayload).
std::vector<uint8_t> SerializeVoiceFrame(const AudioPose& frame);

}  // namespace holo::audio
