#include "audio/voice_chain.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <queue>
#include <random>

#include "protocol/messages.h"

namespace holo::audio {

Status NetworkSimOptions::Check() const {
  if (!(base_delay_ms >= 0 && base_delay_ms <= 10000)) return InvalidArgument("network delay must be in 0..10000 ms");
  if (!(jitter_ms >= 0 && jitter_ms <= 10000)) return InvalidArgument("network jitter must be in 0..10000 ms");
  if (!(loss >= 0 && loss <= 1)) return InvalidArgument("network loss must be in 0..1");
  return OkStatus();
}

Status VoiceChainOptions::Check() const {
  HOLO_RETURN_IF_ERROR(encoder.Check());
  HOLO_RETURN_IF_ERROR(network.Check());
  HOLO_RETURN_IF_ERROR(jitter_buffer.Check());
  HOLO_RETURN_IF_ERROR(spatializer.Check());
  if (!(playout_phase_ms >= 0 && playout_phase_ms < 20)) return InvalidArgument("playout phase must be in [0, 20) ms");
  if (!(tail_ms >= 0 && tail_ms <= 60000)) return InvalidArgument("tail must be in 0..60000 ms");
  return OkStatus();
}

StatusOr<ChainStats> RunVoiceChain(VoiceCapture& capture, SimulatedClock& clock, const VoiceChainOptions& options,
                                   const std::function<void(const ChainTick&)>& on_tick) {
  HOLO_RETURN_IF_ERROR(options.Check());
  if (capture.is_device()) return InvalidArgument("the simulated voice chain needs a file capture, not a device");
  HOLO_ASSIGN_OR_RETURN(auto encoder, VoiceEncoder::Create(options.encoder));
  HOLO_ASSIGN_OR_RETURN(auto jb, JitterBuffer::Create(options.encoder.codec, clock, options.jitter_buffer));
  HOLO_ASSIGN_OR_RETURN(auto sp, Spatializer::Create(options.spatializer));
  HOLO_ASSIGN_OR_RETURN(const int speaker, sp->AddSpeaker());
  sp->SetListener(options.listener);
  ChainStats stats;
  stats.hrtf_status = sp->hrtf_status();
  // One block of silence queued ahead, so the OpenAL source never runs dry
  // between blocks (a stop/restart would click and reset its filters).
  const std::vector<float> silence(kFrameSamples, 0.0f);
  HOLO_RETURN_IF_ERROR(sp->Push(speaker, silence));

  struct InFlight {
    int64_t arrive_us;
    int64_t order;
    std::vector<uint8_t> bytes;
    bool operator>(const InFlight& o) const { return arrive_us != o.arrive_us ? arrive_us > o.arrive_us : order > o.order; }
  };
  std::priority_queue<InFlight, std::vector<InFlight>, std::greater<>> network;
  std::mt19937_64 rng(options.network.seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);

  const int64_t start_us = clock.NowUs();
  int64_t next_capture_us = start_us + kFrameUs;  // the first frame is complete 20 ms in
  const auto phase_us = static_cast<int64_t>(options.playout_phase_ms * 1000.0);
  int64_t next_pull_us = start_us + phase_us;
  bool capture_done = false;
  int64_t end_us = INT64_MAX;
  const auto tail_us = static_cast<int64_t>(options.tail_ms * 1000.0);
  int64_t order = 0;
  protocol::HeadPose queued_pose;  // pose of the block queued in OpenAL (rendered next tick)
  std::vector<float> queued_mono(kFrameSamples, 0.0f);
  bool queued_playing = false;

  while (true) {
    const int64_t next_arrival = network.empty() ? INT64_MAX : network.top().arrive_us;
    const int64_t next_cap = capture_done ? INT64_MAX : next_capture_us;
    if (next_pull_us >= end_us && next_arrival == INT64_MAX) break;
    if (next_pull_us >= end_us && next_pull_us <= std::min(next_cap, next_arrival)) break;
    if (next_cap <= next_arrival && next_cap <= next_pull_us) {
      auto frame = capture.Next();  // sleeps (jumps) to the frame's completion
      if (!frame.ok()) {
        if (frame.status().code() != StatusCode::kOutOfRange) return frame.status();
        capture_done = true;
        end_us = clock.NowUs() + tail_us;
        stats.jitter_buffer_speech_end = jb->stats();
        continue;
      }
      ++stats.frames_captured;
      HOLO_ASSIGN_OR_RETURN(AudioPose ap,
                            encoder->EncodeFrame(frame->samples, frame->sequence, frame->capture_time_us, frame->pose));
      protocol::Header h;
      h.type = protocol::MessageType::kAudioPose;
      h.stream_id = 1;
      h.sequence = frame->sequence;
      h.capture_time_us = frame->capture_time_us;
      std::vector<uint8_t> msg = protocol::EncodeMessage(h, ap);
      ++stats.messages_sent;
      stats.bytes_sent += static_cast<int64_t>(msg.size());
      if (u01(rng) < options.network.loss) {
        ++stats.lost_in_network;
      } else {
        const double delay_ms = options.network.base_delay_ms + u01(rng) * options.network.jitter_ms;
        network.push({clock.NowUs() + static_cast<int64_t>(std::llround(delay_ms * 1000.0)), order++, std::move(msg)});
      }
      next_capture_us += kFrameUs;
    } else if (next_arrival <= next_pull_us) {
      InFlight p = network.top();
      network.pop();
      clock.SetUs(std::max(clock.NowUs(), p.arrive_us));
      // The receiver treats the bytes as untrusted: protocol decode, then the audio path's checks.
      auto m = protocol::DecodeMessage(p.bytes);
      const AudioPose* ap = m.ok() ? std::get_if<AudioPose>(&m->payload) : nullptr;
      if (ap == nullptr || !jb->Insert(*ap).ok()) ++stats.refused;
    } else {
      clock.SetUs(std::max(clock.NowUs(), next_pull_us));
      const std::vector<float> mono = jb->Pull();
      const bool playing = jb->playing();
      const protocol::HeadPose pose = jb->pose();
      HOLO_RETURN_IF_ERROR(sp->Push(speaker, mono));
      // The block rendered now is the one queued a tick ago: place the source
      // where that block's speaker was.
      ChainTick t;
      t.time_us = next_pull_us;
      t.playing = queued_playing;
      t.remote_head = queued_pose;
      t.placement = PlaceRemoteSpeaker(queued_pose, options.link);
      HOLO_RETURN_IF_ERROR(sp->SetSpeaker(speaker, t.placement));
      const std::vector<float> stereo = sp->Render(kFrameSamples);
      t.stereo = stereo;
      t.source = queued_mono;
      t.azimuth_deg = AzimuthDeg(options.listener, t.placement.position);
      t.distance_m = (t.placement.position - Eigen::Vector3f(options.listener.x, options.listener.y, options.listener.z)).norm();
      t.gain = sp->SpeakerGain(speaker);
      queued_pose = pose;
      queued_playing = playing;
      on_tick(t);
      queued_mono = mono;
      next_pull_us += kFrameUs;
    }
  }
  stats.jitter_buffer = jb->stats();
  return stats;
}

StatusOr<MouthToEar> MeasureMouthToEar(const VoiceChainOptions& options, double seconds, double warmup_s) {
  if (!(seconds >= 2 && seconds <= 600) || !(warmup_s >= 0 && warmup_s < seconds - 1)) {
    return InvalidArgument("mouth-to-ear: need 2..600 s and a warm-up at least 1 s shorter");
  }
  constexpr double kPeriod = 0.5, kBurst = 0.010, kOffset = 0.1037;
  const size_t n = static_cast<size_t>(seconds * kSampleRate);
  std::vector<float> in(n, 0.0f);
  std::vector<double> in_centroid;
  const size_t len = static_cast<size_t>(kBurst * kSampleRate);
  for (double t0 = kOffset; t0 + kPeriod < seconds; t0 += kPeriod) {
    const size_t a = static_cast<size_t>(t0 * kSampleRate);
    double num = 0, den = 0;
    for (size_t i = 0; i < len; ++i) {
      const double w = 0.5 - 0.5 * std::cos(2 * std::numbers::pi * (static_cast<double>(i) + 0.5) / static_cast<double>(len));
      in[a + i] = static_cast<float>(0.5 * w * std::sin(2 * std::numbers::pi * 1000.0 * static_cast<double>(i) / kSampleRate));
      const double e = static_cast<double>(in[a + i]) * in[a + i];
      num += static_cast<double>(a + i) / kSampleRate * e;
      den += e;
    }
    in_centroid.push_back(num / den);
  }
  // The source 1 m ahead of the listener in the local room, facing them, as a
  // pose in the remote room.
  const Eigen::Isometry3f room_from_listener = HeadToRoom(options.listener);
  const Eigen::Vector3f local = room_from_listener * Eigen::Vector3f(1, 0, 0);
  const Eigen::Vector3f facing = -(room_from_listener.linear() * Eigen::Vector3f::UnitX());
  const Eigen::Isometry3f remote_from_local = options.link.local_from_remote.inverse();
  const Eigen::Vector3f rp = remote_from_local * local, rf = remote_from_local.linear() * facing;
  const protocol::HeadPose speaker{rp.x(), rp.y(), rp.z(), std::atan2(rf.y(), rf.x()), 0.0f, 0.0f};
  SimulatedClock clock(0);
  auto cap = VoiceCapture::FromSamples(std::move(in), clock, [&](int64_t) { return speaker; }, "bursts");
  std::vector<float> ear;  // (L + R) / 2 on the ear timeline, from t = 0
  auto on_tick = [&](const ChainTick& t) {
    const size_t at = static_cast<size_t>(t.time_us * kSampleRate / 1000000);
    if (ear.size() < at + kFrameSamples) ear.resize(at + kFrameSamples, 0.0f);
    for (int i = 0; i < kFrameSamples; ++i) ear[at + i] = 0.5f * (t.stereo[2 * i] + t.stereo[2 * i + 1]);
  };
  HOLO_ASSIGN_OR_RETURN(ChainStats st, RunVoiceChain(*cap, clock, options, on_tick));
  std::vector<double> delays;
  for (double c : in_centroid) {
    if (c < warmup_s) continue;
    // The burst's output lies in [c, c + 450 ms): later bursts come 500 ms on.
    const size_t a = static_cast<size_t>(c * kSampleRate);
    const size_t b = std::min(ear.size(), a + static_cast<size_t>(0.45 * kSampleRate));
    double num = 0, den = 0;
    for (size_t i = a; i < b; ++i) {
      const double e = static_cast<double>(ear[i]) * ear[i];
      num += static_cast<double>(i) / kSampleRate * e;
      den += e;
    }
    if (den > 0) delays.push_back((num / den - c) * 1000.0);
  }
  if (delays.empty()) return Internal("mouth-to-ear: no burst reached the ears");
  std::sort(delays.begin(), delays.end());
  MouthToEar m;
  m.bursts = static_cast<int>(delays.size());
  const size_t k = delays.size();
  m.median_ms = k % 2 == 1 ? delays[k / 2] : 0.5 * (delays[k / 2 - 1] + delays[k / 2]);
  m.p95_ms = delays[std::min(k - 1, static_cast<size_t>(0.95 * static_cast<double>(k)))];
  m.min_ms = delays.front();
  m.max_ms = delays.back();
  m.jb_target_ms = st.jitter_buffer.target_delay_ms;
  m.poses_interpolated = st.jitter_buffer.poses_interpolated;
  m.poses_extrapolated = st.jitter_buffer.poses_extrapolated;
  m.poses_held = st.jitter_buffer.poses_held;
  return m;
}

}  // namespace holo::audio
