#include "audio/voice_codec.h"

#include <opus/opus.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace holo::audio {
namespace {

std::string OpusError(int code) { return std::string(opus_strerror(code)) + " (" + std::to_string(code) + ")"; }

}  // namespace

bool IsOpus(AudioCodec codec) { return codec == AudioCodec::kOpus || codec == AudioCodec::kOpusLean; }

VoiceEncoderOptions LeanVoiceEncoderOptions() {
  VoiceEncoderOptions o;
  o.codec = AudioCodec::kOpusLean;
  o.bitrate_bps = 14000;
  o.voip_application = false;
  o.pose_every = 2;
  return o;
}

Status VoiceEncoderOptions::Check() const {
  if (!IsOpus(codec) && codec != AudioCodec::kPcm16) {
    return InvalidArgument("codec must be opus, opus-lean or pcm, got " + std::to_string(static_cast<int>(codec)));
  }
  if (max_bandwidth_hz != 0 && max_bandwidth_hz != 8000 && max_bandwidth_hz != 12000 && max_bandwidth_hz != 16000 &&
      max_bandwidth_hz != 24000 && max_bandwidth_hz != 48000) {
    return InvalidArgument("max_bandwidth_hz must be 0, 8000, 12000, 16000, 24000 or 48000, got " +
                           std::to_string(max_bandwidth_hz));
  }
  if (pose_every != 1 && pose_every != 2) {
    return InvalidArgument("pose_every must be 1 or 2, got " + std::to_string(pose_every));
  }
  if (pose_every != 1 && codec != AudioCodec::kOpusLean) {
    return InvalidArgument("pose_every 2 needs the lean frame (codec opus-lean)");
  }
  if (bitrate_bps < 6000 || bitrate_bps > 510000) {
    return InvalidArgument("bitrate_bps must be in 6000..510000, got " + std::to_string(bitrate_bps));
  }
  if (expected_loss_pct < 0 || expected_loss_pct > 100) {
    return InvalidArgument("expected_loss_pct must be in 0..100, got " + std::to_string(expected_loss_pct));
  }
  if (complexity < 0 || complexity > 10) {
    return InvalidArgument("complexity must be in 0..10, got " + std::to_string(complexity));
  }
  return OkStatus();
}

StatusOr<std::unique_ptr<VoiceEncoder>> VoiceEncoder::Create(const VoiceEncoderOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<VoiceEncoder> e(new VoiceEncoder());
  e->options_ = options;
  if (IsOpus(options.codec)) {
    int err = 0;
    e->enc_ = opus_encoder_create(kSampleRate, 1,
                                  options.voip_application ? OPUS_APPLICATION_VOIP : OPUS_APPLICATION_AUDIO, &err);
    if (err != OPUS_OK || e->enc_ == nullptr) return Internal("opus_encoder_create: " + OpusError(err));
    int bandwidth = OPUS_BANDWIDTH_FULLBAND;
    switch (options.max_bandwidth_hz) {
      case 8000: bandwidth = OPUS_BANDWIDTH_NARROWBAND; break;
      case 12000: bandwidth = OPUS_BANDWIDTH_MEDIUMBAND; break;
      case 16000: bandwidth = OPUS_BANDWIDTH_WIDEBAND; break;
      case 24000: bandwidth = OPUS_BANDWIDTH_SUPERWIDEBAND; break;
      default: break;
    }
    const int settings[][2] = {{OPUS_SET_BITRATE_REQUEST, options.bitrate_bps},
                               {OPUS_SET_INBAND_FEC_REQUEST, options.fec ? 1 : 0},
                               {OPUS_SET_PACKET_LOSS_PERC_REQUEST, options.expected_loss_pct},
                               {OPUS_SET_COMPLEXITY_REQUEST, options.complexity},
                               {OPUS_SET_SIGNAL_REQUEST, OPUS_SIGNAL_VOICE},
                               {OPUS_SET_VBR_REQUEST, options.rate_control == OpusRateControl::kCbr ? 0 : 1},
                               {OPUS_SET_VBR_CONSTRAINT_REQUEST,
                                options.rate_control == OpusRateControl::kConstrainedVbr ? 1 : 0},
                               {OPUS_SET_MAX_BANDWIDTH_REQUEST, bandwidth}};
    for (const auto& s : settings) {
      err = opus_encoder_ctl(e->enc_, s[0], s[1]);
      if (err != OPUS_OK) return Internal("opus_encoder_ctl(" + std::to_string(s[0]) + "): " + OpusError(err));
    }
  }
  return e;
}

VoiceEncoder::~VoiceEncoder() {
  if (enc_ != nullptr) opus_encoder_destroy(enc_);
}

int CodecDelaySamples(AudioCodec codec) { return IsOpus(codec) ? 312 : 0; }

int64_t SkipStalledFrames(int64_t now_us, int64_t max_behind_us, int64_t* next_us, uint32_t* sequence) {
  const int64_t behind = now_us - *next_us;
  if (behind <= max_behind_us) return 0;
  const int64_t skip = behind / kFrameUs;
  *next_us += skip * kFrameUs;
  *sequence += static_cast<uint32_t>(skip);
  return skip;
}

int VoiceEncoder::lookahead_samples() const {
  if (enc_ == nullptr) return 0;
  opus_int32 lookahead = 0;
  if (opus_encoder_ctl(enc_, OPUS_GET_LOOKAHEAD(&lookahead)) != OPUS_OK) return 0;
  return static_cast<int>(lookahead);
}

StatusOr<std::vector<uint8_t>> VoiceEncoder::Encode(std::span<const float> pcm) {
  if (pcm.size() != kFrameSamples) {
    return InvalidArgument("a voice frame is " + std::to_string(kFrameSamples) + " samples, got " +
                           std::to_string(pcm.size()));
  }
  if (options_.codec == AudioCodec::kPcm16) {
    std::vector<uint8_t> out(kFrameSamples * 2);
    for (int i = 0; i < kFrameSamples; ++i) {
      const float v = std::clamp(pcm[i], -1.0f, 1.0f);
      const auto s = static_cast<int16_t>(std::lrint(v * 32767.0f));
      const auto u = static_cast<uint16_t>(s);
      out[2 * i] = static_cast<uint8_t>(u & 0xFF);
      out[2 * i + 1] = static_cast<uint8_t>(u >> 8);
    }
    return out;
  }
  std::vector<uint8_t> out(kMaxOpusPacket);
  const int n = opus_encode_float(enc_, pcm.data(), kFrameSamples, out.data(), static_cast<opus_int32>(out.size()));
  if (n < 0) return Internal("opus_encode_float: " + OpusError(n));
  out.resize(static_cast<size_t>(n));
  return out;
}

StatusOr<AudioPose> VoiceEncoder::EncodeFrame(std::span<const float> pcm, uint32_t sequence,
                                              int64_t capture_time_us, const HeadPose& pose) {
  AudioPose f;
  f.codec = options_.codec;
  f.channels = 1;
  f.sample_rate = kSampleRate;
  f.duration_us_div10 = static_cast<uint16_t>(kFrameUs / 10);
  f.sequence = sequence;
  f.capture_time_us = capture_time_us;
  f.pose = pose;
  HOLO_ASSIGN_OR_RETURN(f.audio, Encode(pcm));
  if (options_.codec == AudioCodec::kOpusLean) {
    f.codec = AudioCodec::kOpus;  // ToLeanAudioPose converts an Opus frame
    f.has_pose = sequence % static_cast<uint32_t>(options_.pose_every) == 0;
    f = protocol::ToLeanAudioPose(std::move(f));
  }
  return f;
}

StatusOr<std::unique_ptr<VoiceDecoder>> VoiceDecoder::Create(AudioCodec codec) {
  if (!IsOpus(codec) && codec != AudioCodec::kPcm16) {
    return InvalidArgument("unknown audio codec " + std::to_string(static_cast<int>(codec)));
  }
  std::unique_ptr<VoiceDecoder> d(new VoiceDecoder());
  d->codec_ = codec;
  if (IsOpus(codec)) {
    int err = 0;
    d->dec_ = opus_decoder_create(kSampleRate, 1, &err);
    if (err != OPUS_OK || d->dec_ == nullptr) return Internal("opus_decoder_create: " + OpusError(err));
  }
  return d;
}

VoiceDecoder::~VoiceDecoder() {
  if (dec_ != nullptr) opus_decoder_destroy(dec_);
}

StatusOr<std::vector<float>> VoiceDecoder::Decode(std::span<const uint8_t> audio) {
  std::vector<float> out(kFrameSamples, 0.0f);
  if (codec_ == AudioCodec::kPcm16) {
    if (audio.size() != 2 * kFrameSamples) {
      return DataLoss("PCM frame must be " + std::to_string(2 * kFrameSamples) + " bytes, got " +
                      std::to_string(audio.size()));
    }
    for (int i = 0; i < kFrameSamples; ++i) {
      const auto u = static_cast<uint16_t>(audio[2 * i] | (audio[2 * i + 1] << 8));
      out[i] = static_cast<float>(static_cast<int16_t>(u)) / 32768.0f;
    }
    return out;
  }
  if (audio.empty() || audio.size() > kMaxOpusPacket) {
    return DataLoss("Opus packet of " + std::to_string(audio.size()) + " bytes (must be 1.." +
                    std::to_string(kMaxOpusPacket) + ")");
  }
  const int n = opus_decode_float(dec_, audio.data(), static_cast<opus_int32>(audio.size()), out.data(),
                                  kFrameSamples, 0);
  if (n < 0) return DataLoss("opus_decode_float: " + OpusError(n));
  if (n != kFrameSamples) return DataLoss("Opus packet decodes to " + std::to_string(n) + " samples, not 960");
  return out;
}

std::vector<float> VoiceDecoder::Conceal(std::span<const uint8_t> next_packet, bool* used_fec) {
  std::vector<float> out(kFrameSamples, 0.0f);
  *used_fec = false;
  if (codec_ == AudioCodec::kPcm16) return out;
  // libopus 1.3 cannot tell whether a packet carries LBRR data; with none,
  // decode_fec = 1 falls back to concealment by itself.
  if (!next_packet.empty() && next_packet.size() <= kMaxOpusPacket) {
    const int n = opus_decode_float(dec_, next_packet.data(), static_cast<opus_int32>(next_packet.size()),
                                    out.data(), kFrameSamples, 1);
    if (n == kFrameSamples) {
      *used_fec = true;
      return out;
    }
  }
  const int n = opus_decode_float(dec_, nullptr, 0, out.data(), kFrameSamples, 0);
  if (n != kFrameSamples) std::fill(out.begin(), out.end(), 0.0f);
  return out;
}

Status ValidateVoiceFrame(const AudioPose& f) {
  if (f.sample_rate != kSampleRate) {
    return DataLoss("voice frame sample_rate must be 48000, got " + std::to_string(f.sample_rate));
  }
  if (f.channels != 1) return DataLoss("voice frame must be mono, got " + std::to_string(f.channels) + " channels");
  if (f.duration_us_div10 != kFrameUs / 10) {
    return DataLoss("voice frame must last 20 ms (2000), got " + std::to_string(f.duration_us_div10));
  }
  const float pos[] = {f.pose.x, f.pose.y, f.pose.z};
  for (float v : pos) {
    if (!std::isfinite(v) || std::fabs(v) > 1000.0f) return DataLoss("head position outside ±1000 m");
  }
  const float ang[] = {f.pose.yaw, f.pose.pitch, f.pose.roll};
  for (float v : ang) {
    if (!std::isfinite(v) || std::fabs(v) > 6.2832f) return DataLoss("head angle outside ±2π");
  }
  if (f.codec == AudioCodec::kPcm16) {
    if (f.audio.size() != 2 * kFrameSamples) {
      return DataLoss("PCM voice frame must be 1920 bytes, got " + std::to_string(f.audio.size()));
    }
  } else if (IsOpus(f.codec)) {
    if (f.audio.empty() || f.audio.size() > kMaxOpusPacket) {
      return DataLoss("Opus voice frame of " + std::to_string(f.audio.size()) + " bytes (must be 1..1275)");
    }
    const int n = opus_packet_get_nb_samples(f.audio.data(), static_cast<opus_int32>(f.audio.size()), kSampleRate);
    if (n < 0) return DataLoss("malformed Opus packet: " + OpusError(n));
    if (n != kFrameSamples) return DataLoss("Opus packet holds " + std::to_string(n) + " samples, not 960");
  } else {
    return DataLoss("unknown audio codec " + std::to_string(static_cast<int>(f.codec)));
  }
  return OkStatus();
}

StatusOr<AudioPose> ParseVoiceFrame(const protocol::Header& header, std::span<const uint8_t> payload) {
  if (header.type != protocol::MessageType::kAudioPose) {
    return DataLoss(std::string("voice frame: header says ") + protocol::MessageTypeName(header.type));
  }
  HOLO_ASSIGN_OR_RETURN(protocol::Payload p, protocol::DecodePayload(header, payload));
  AudioPose* f = std::get_if<AudioPose>(&p);
  if (f == nullptr) return DataLoss("payload is not an AudioPose");
  HOLO_RETURN_IF_ERROR(ValidateVoiceFrame(*f));
  return std::move(*f);
}

StatusOr<AudioPose> ParseVoiceFrame(std::span<const uint8_t> payload) {
  if (!payload.empty() && payload[0] == static_cast<uint8_t>(AudioCodec::kOpusLean)) {
    return DataLoss("voice frame: a lean frame (codec 3) needs its message header for sequence and capture time");
  }
  protocol::Header h;
  h.type = protocol::MessageType::kAudioPose;
  return ParseVoiceFrame(h, payload);
}

std::vector<uint8_t> SerializeVoiceFrame(const AudioPose& frame) { return protocol::EncodePayload(frame); }

}  // namespace holo::audio
