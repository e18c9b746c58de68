// WAV reading (validated), writing and resampling for the voice path.
#include "audio/wav.h"

#include <soxr.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

#include "protocol/byte_io.h"

namespace holo::audio {
namespace {

constexpr uint16_t kFormatPcm = 1;
constexpr uint16_t kFormatFloat = 3;
constexpr uint16_t kFormatExtensible = 0xFFFE;
// Data sizes streaming writers put in the header before they know the length
// (0, or "as large as possible"): the data then runs to the end of the file.
bool StreamedSize(uint32_t size) { return size == 0 || size >= 0x7FFFF000u; }

void Put16(std::vector<uint8_t>& v, uint16_t x) {
  v.push_back(static_cast<uint8_t>(x & 0xFF));
  v.push_back(static_cast<uint8_t>(x >> 8));
}
void PutTag(std::vector<uint8_t>& v, const char* tag) {
  for (int i = 0; i < 4; ++i) v.push_back(static_cast<uint8_t>(tag[i]));
}
void Put32(std::vector<uint8_t>& v, uint32_t x) {
  for (int i = 0; i < 4; ++i) v.push_back(static_cast<uint8_t>((x >> (8 * i)) & 0xFF));
}

float SampleAt(const uint8_t* p, uint16_t format, uint16_t bits) {
  if (format == kFormatFloat) {
    double v = 0;
    if (bits == 32) {
      float f = 0;
      std::memcpy(&f, p, 4);
      v = f;
    } else {
      std::memcpy(&v, p, 8);
    }
    return std::isfinite(v) ? static_cast<float>(std::clamp(v, -1.0, 1.0)) : 0.0f;
  }
  switch (bits) {
    case 8:
      return (static_cast<float>(p[0]) - 128.0f) / 128.0f;
    case 16:
      return static_cast<float>(static_cast<int16_t>(static_cast<uint16_t>(p[0] | (p[1] << 8)))) / 32768.0f;
    case 24: {
      const uint32_t u = static_cast<uint32_t>(p[0]) << 8 | static_cast<uint32_t>(p[1]) << 16 |
                         static_cast<uint32_t>(p[2]) << 24;
      return static_cast<float>(static_cast<int32_t>(u)) / 2147483648.0f;
    }
    default: {
      int32_t v = 0;
      std::memcpy(&v, p, 4);
      return static_cast<float>(static_cast<double>(v) / 2147483648.0);
    }
  }
}

}  // namespace

StatusOr<WavAudio> ParseWav(std::span<const uint8_t> bytes) {
  if (bytes.size() > kMaxWavFileBytes) {
    return DataLoss("WAV file of " + std::to_string(bytes.size()) + " bytes exceeds the limit of " +
                    std::to_string(kMaxWavFileBytes));
  }
  protocol::ByteReader r(bytes);
  std::span<const uint8_t> tag;
  uint32_t riff_size = 0;
  if (bytes.size() < 12) return DataLoss("not a WAV file: " + std::to_string(bytes.size()) + " bytes, a RIFF header is 12");
  HOLO_RETURN_IF_ERROR(r.View("wav.riff", 4, &tag));
  if (std::memcmp(tag.data(), "RIFF", 4) != 0) return DataLoss("not a RIFF file (no 'RIFF' tag)");
  HOLO_RETURN_IF_ERROR(r.U32("wav.riff_size", &riff_size));
  HOLO_RETURN_IF_ERROR(r.View("wav.wave", 4, &tag));
  if (std::memcmp(tag.data(), "WAVE", 4) != 0) return DataLoss("RIFF file is not WAVE (no 'WAVE' tag)");
  uint16_t format = 0, channels = 0, bits = 0, align = 0;
  uint32_t rate = 0, byte_rate = 0;
  bool have_fmt = false, have_data = false;
  std::span<const uint8_t> data;
  while (r.remaining() >= 8) {
    std::span<const uint8_t> id;
    uint32_t size = 0;
    HOLO_RETURN_IF_ERROR(r.View("wav.chunk_id", 4, &id));
    HOLO_RETURN_IF_ERROR(r.U32("wav.chunk_size", &size));
    const std::string name(reinterpret_cast<const char*>(id.data()), 4);
    const bool is_data = name == "data";
    size_t take = size;
    if (size > r.remaining()) {
      if (!(is_data && StreamedSize(size))) {
        return DataLoss("truncated: chunk '" + name + "' declares " + std::to_string(size) + " bytes, only " +
                        std::to_string(r.remaining()) + " remain");
      }
      take = r.remaining();  // streamed: data to the end of the file
    } else if (is_data && size == 0) {
      take = r.remaining();
    }
    std::span<const uint8_t> body;
    HOLO_RETURN_IF_ERROR(r.View("wav.chunk", take, &body));
    if (take % 2 == 1 && r.remaining() > 0) HOLO_RETURN_IF_ERROR(r.View("wav.pad", 1, &tag));
    if (name == "fmt ") {
      if (have_fmt) return DataLoss("two 'fmt ' chunks");
      protocol::ByteReader f(body);
      HOLO_RETURN_IF_ERROR(f.U16("wav.fmt.format", &format));
      HOLO_RETURN_IF_ERROR(f.U16("wav.fmt.channels", &channels));
      HOLO_RETURN_IF_ERROR(f.U32("wav.fmt.sample_rate", &rate));
      HOLO_RETURN_IF_ERROR(f.U32("wav.fmt.byte_rate", &byte_rate));
      HOLO_RETURN_IF_ERROR(f.U16("wav.fmt.block_align", &align));
      HOLO_RETURN_IF_ERROR(f.U16("wav.fmt.bits_per_sample", &bits));
      if (format == kFormatExtensible) {
        uint16_t cb_size = 0, valid_bits = 0;
        uint32_t channel_mask = 0;
        std::span<const uint8_t> guid;
        HOLO_RETURN_IF_ERROR(f.U16("wav.fmt.cb_size", &cb_size));
        if (cb_size < 22) return DataLoss("WAVE_FORMAT_EXTENSIBLE with an extension of " + std::to_string(cb_size) + " bytes (22 needed)");
        HOLO_RETURN_IF_ERROR(f.U16("wav.fmt.valid_bits", &valid_bits));
        HOLO_RETURN_IF_ERROR(f.U32("wav.fmt.channel_mask", &channel_mask));
        HOLO_RETURN_IF_ERROR(f.View("wav.fmt.subformat", 16, &guid));
        format = static_cast<uint16_t>(guid[0] | (guid[1] << 8));
      }
      have_fmt = true;
    } else if (is_data) {
      if (have_data) return DataLoss("two 'data' chunks");
      data = body;
      have_data = true;
    }
  }
  if (!have_fmt) return DataLoss("no 'fmt ' chunk");
  if (!have_data) return DataLoss("no 'data' chunk");
  const bool pcm = format == kFormatPcm && (bits == 8 || bits == 16 || bits == 24 || bits == 32);
  const bool flt = format == kFormatFloat && (bits == 32 || bits == 64);
  if (!pcm && !flt) {
    return DataLoss("unsupported sample format " + std::to_string(format) + " with " + std::to_string(bits) +
                    " bits (PCM 8/16/24/32 or float 32/64 expected)");
  }
  if (channels < 1 || channels > 32) return DataLoss("channel count " + std::to_string(channels) + " outside 1..32");
  if (rate < 1000 || rate > 384000) return DataLoss("sample rate " + std::to_string(rate) + " Hz outside 1000..384000");
  const size_t sample_bytes = bits / 8u;
  const size_t frame_bytes = static_cast<size_t>(channels) * sample_bytes;
  if (align != frame_bytes) {
    return DataLoss("block_align " + std::to_string(align) + " does not match " + std::to_string(channels) +
                    " channels of " + std::to_string(bits) + " bits (" + std::to_string(frame_bytes) + ")");
  }
  const size_t n = data.size() / frame_bytes;
  if (n == 0) return DataLoss("no audio samples (data chunk of " + std::to_string(data.size()) + " bytes)");
  if (static_cast<double>(n) / rate > kMaxWavSeconds) {
    return DataLoss("audio of " + std::to_string(static_cast<double>(n) / rate) + " s exceeds the limit of " +
                    std::to_string(static_cast<int>(kMaxWavSeconds)) + " s");
  }
  WavAudio w;
  w.sample_rate = static_cast<int>(rate);
  w.channels = channels;
  w.samples.resize(n * channels);
  for (size_t i = 0; i < n * channels; ++i) w.samples[i] = SampleAt(data.data() + i * sample_bytes, format, bits);
  return w;
}

StatusOr<WavAudio> ReadWav(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return NotFound("cannot open " + path);
  const std::streamoff size = in.tellg();
  if (size < 0) return DataLoss(path + ": cannot determine the file size");
  if (static_cast<uint64_t>(size) > kMaxWavFileBytes) {
    return DataLoss(path + ": " + std::to_string(size) + " bytes exceeds the WAV limit of " +
                    std::to_string(kMaxWavFileBytes));
  }
  std::vector<uint8_t> bytes(static_cast<size_t>(size));
  in.seekg(0);
  in.read(reinterpret_cast<char*>(bytes.data()), size);
  if (!in) return DataLoss(path + ": read failed");
  auto w = ParseWav(bytes);
  if (!w.ok()) return Status(w.status().code(), path + ": " + w.status().message());
  return w;
}

StatusOr<std::vector<float>> Resample(std::span<const float> in, int in_rate, int out_rate) {
  if (in_rate < 1000 || in_rate > 384000 || out_rate < 8000 || out_rate > 192000) {
    return InvalidArgument("resampling " + std::to_string(in_rate) + " -> " + std::to_string(out_rate) +
                           " Hz: rates outside 1000..384000 / 8000..192000");
  }
  if (in_rate == out_rate || in.empty()) return std::vector<float>(in.begin(), in.end());
  const size_t out_len = static_cast<size_t>(
      std::ceil(static_cast<double>(in.size()) * out_rate / static_cast<double>(in_rate)));
  std::vector<float> out(out_len);
  size_t done = 0;
  const soxr_io_spec_t io = soxr_io_spec(SOXR_FLOAT32_I, SOXR_FLOAT32_I);
  const soxr_quality_spec_t q = soxr_quality_spec(SOXR_HQ, 0);
  const soxr_error_t err = soxr_oneshot(in_rate, out_rate, 1, in.data(), in.size(), nullptr, out.data(), out_len,
                                        &done, &io, &q, nullptr);
  if (err != nullptr) return Internal(std::string("soxr_oneshot: ") + err);
  out.resize(done);
  return out;
}

StatusOr<std::vector<float>> ReadMonoWav(const std::string& path, int target_rate) {
  if (target_rate < 8000 || target_rate > 192000) return InvalidArgument("target_rate outside 8000..192000");
  HOLO_ASSIGN_OR_RETURN(WavAudio w, ReadWav(path));
  const size_t n = w.frames();
  std::vector<float> mono(n);
  for (size_t i = 0; i < n; ++i) {
    float acc = 0;
    for (int c = 0; c < w.channels; ++c) acc += w.samples[i * w.channels + c];
    mono[i] = acc / static_cast<float>(w.channels);
  }
  return Resample(mono, w.sample_rate, target_rate);
}

Status WriteWav(const std::string& path, std::span<const float> interleaved, int channels, int sample_rate) {
  if (channels < 1 || channels > 32) return InvalidArgument("WAV channel count " + std::to_string(channels));
  if (interleaved.size() * 2 > 0xFFFFFFF0u - 36) return InvalidArgument("too much audio for one WAV file");
  const uint32_t data_bytes = static_cast<uint32_t>(interleaved.size() * 2);
  const auto ch = static_cast<uint16_t>(channels);
  std::vector<uint8_t> b;
  b.reserve(44 + data_bytes);
  PutTag(b, "RIFF");
  Put32(b, 36 + data_bytes);
  PutTag(b, "WAVE");
  PutTag(b, "fmt ");
  Put32(b, 16);
  Put16(b, kFormatPcm);
  Put16(b, ch);
  Put32(b, static_cast<uint32_t>(sample_rate));
  Put32(b, static_cast<uint32_t>(sample_rate) * 2u * ch);
  Put16(b, static_cast<uint16_t>(2 * ch));
  Put16(b, 16);
  PutTag(b, "data");
  Put32(b, data_bytes);
  for (float f : interleaved) {
    const float c = std::isfinite(f) ? std::fmax(-1.0f, std::fmin(1.0f, f)) : 0.0f;
    Put16(b, static_cast<uint16_t>(static_cast<int16_t>(std::lrint(c * 32767.0f))));
  }
  std::ofstream out(path, std::ios::binary);
  if (!out) return Unavailable("cannot write " + path);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  if (!out) return Unavailable("write failed: " + path);
  return OkStatus();
}

Status WriteStereoWav(const std::string& path, std::span<const float> interleaved, int sample_rate) {
  return WriteWav(path, interleaved, 2, sample_rate);
}

Status WriteMonoWav(const std::string& path, std::span<const float> mono, int sample_rate) {
  return WriteWav(path, mono, 1, sample_rate);
}

}  // namespace holo::audio
