#include "audio/voice_chain.h"

#include <algorithm>
#include <cmath>
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

}  // namespace holo::audio
