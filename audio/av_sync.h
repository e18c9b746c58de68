// Lip sync at a viewer: a site's voices and its picture are played so that
// what was captured at the same instant is heard and seen at the same time
// (docs/live.md "Voice and picture in sync").
//
// Both streams carry capture times on the site's clock (the pods'
// acquisition time for the picture, the first sample's time for a voice).
// Each stream has a *natural* delay, capture → output, when nothing waits for
// the other: the voice's is its jitter buffer's own (network, jitter target,
// one frame, output buffer), the picture's is decode + queue + render. The
// stream that arrives first waits for the other, within a bound:
//  * picture later than voice (the usual case: fusion and rendering take
//    hundreds of ms): the voice is delayed to the pictures' delay — 90 % of
//    the pictures of the last `window_s` are ready by then, and each of those
//    is held until its voice plays (`hold_pictures`; the others are shown
//    as soon as they are ready, their voice a little early) — but never by
//    more than
//    `max_voice_delay_ms` over its natural delay; beyond it the voice plays
//    at the bound and leads the picture (counted);
//  * voice later than picture (a slow voice path): each picture is held
//    until its voice plays, at most `max_picture_delay_ms` after it was
//    ready; beyond it the picture is shown at the bound and the voice lags
//    (counted). A picture never waits for a voice that is not playing.
// Viewers notice voice ahead of the lips at 45 ms and behind at 125 ms
// (ITU-R BT.1359): the offsets beyond are counted.
// Neither stream ever stops for the other: the voice keeps its 20 ms pace,
// pictures keep coming, only their delays change.
//
// The measure: for each picture displayed while a voice plays, av offset =
// (voice playout time − picture display time) for the same capture instant
// = voice delay now − that picture's capture → display delay; positive =
// voice late. Clock offsets between site and viewer cancel (both delays use
// the same clocks).
//
// Times are µs: capture times on the site's clock, all others on one viewer
// clock. Thread-safe (one mutex): the voice playout thread and the render
// loop call it.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <vector>

#include "common/status.h"

namespace holo::audio {

struct AvSyncOptions {
  // Off: nothing waits for the other stream; offsets are still measured
  // (what a viewer without lip sync would show).
  bool enabled = true;
  // Largest extra delay given to a voice to wait for a later picture, ms. The
  // live run on a 2-core machine shows pictures 0.3–0.9 s after capture;
  // waiting costs conversation delay the picture already has.
  double max_voice_delay_ms = 1000.0;
  // Largest hold of a picture to wait for a later voice, ms (held pictures
  // are kept decoded in memory).
  double max_picture_delay_ms = 300.0;
  // How the two meet when pictures arrive later than the voice:
  //  * true (a picture jitter buffer): the voice follows `picture_quantile`
  //    of the pictures' natural delays (ready + render, no hold) over the
  //    window, and every picture that would be seen before its voice is
  //    held until the voice plays. Most pictures are in sync however much
  //    their delays spread, at the cost of that quantile's picture delay
  //    (p90 − p50 more latency for the median picture).
  //  * false: pictures are held only when the voice's own delay is longer;
  //    the voice follows the displayed pictures' delays (the delay within
  //    35 ms of their median that puts the most within the window below).
  //    No latency added to pictures; offsets spread as their delays do.
  bool hold_pictures = true;
  double picture_quantile = 0.9;
  // Pictures that arrive in bursts are shown at the rhythm they were
  // captured in, voice or not: while no voice plays, each picture waits
  // until `picture_quantile` of the pictures' natural delays over the window
  // has passed since its capture (at most max_picture_delay_ms). A broadcast
  // needs it: its player receives a part's quarter second of frames at once,
  // and without pacing the viewer shows the newest of each and skips the
  // rest. Only differences of capture times count, so a stream whose capture
  // clock is not this machine's is paced as well. Off by default (a call's
  // pictures arrive as they are made); holoport-client --http turns it on.
  bool pace_pictures = false;
  // Pictures' delays the voice follows: this window, seconds. Short enough
  // to follow a site whose latency swings (a loaded site catching up);
  // each move of the voice costs a resampled stretch, a dropped or a
  // concealed frame. (On a loaded 2-core run, replaying its picture delays:
  // 0.5 s → 91 % of decoded pictures within BT.1359, 1 s → 79 %, 2 s → 59 %.)
  double window_s = 1.0;
  // The voice delay moves only when the wanted delay differs by more, ms,
  // and at most every `update_interval_ms` (each move costs the voice a
  // resampled stretch, a dropped or a concealed frame).
  double deadband_ms = 10.0;
  double update_interval_ms = 250.0;
  // ITU-R BT.1359 detectability thresholds, ms: voice ahead of the picture
  // by more than `early_limit_ms`, or behind by more than `late_limit_ms`.
  double early_limit_ms = 45.0;
  double late_limit_ms = 125.0;
  // A voice counts as playing this long after its last playout, ms.
  double voice_timeout_ms = 200.0;
  // Keep one TracePoint per picture displayed while a voice plays (trace()).
  bool keep_trace = false;
  Status Check() const;
};

// One measured offset, for plots and debugging (AvSyncOptions::keep_trace).
struct AvSyncTracePoint {
  int64_t display_us = 0, capture_us = 0;
  uint32_t stream = 0;
  double picture_delay_ms = 0, hold_ms = 0;      // capture → displayed; of it, held for the voice
  double voice_delay_ms = 0, voice_natural_ms = 0, voice_target_ms = 0;
  double offset_ms = 0;                          // voice_delay − picture_delay
};

struct AvSyncStats {
  int64_t pictures = 0;             // pictures displayed
  int64_t pictures_held = 0;        // of them, held back for a later voice (or paced: pace_pictures)
  int64_t pictures_hold_capped = 0; // the voice was later than max_picture_delay_ms allowed
  int64_t voice_delay_capped = 0;   // voice target updates limited by max_voice_delay_ms
  int64_t offsets = 0;              // av offsets measured (a picture displayed while a voice played)
  int64_t offsets_early = 0;        // voice ahead by more than early_limit_ms
  int64_t offsets_late = 0;         // voice behind by more than late_limit_ms
  // Offsets over the measured pictures, ms (0 without samples).
  double av_offset_ms_p1 = 0, av_offset_ms_p50 = 0, av_offset_ms_p99 = 0;
  // The offsets the same pictures would have had without sync: the voice's
  // natural delay − the picture's delay without its hold (median, ms).
  double unsynced_offset_ms_p50 = 0;
  // Now: capture → playout the voice has without sync, the delay asked of it
  // for sync (0: none), and what it has.
  double voice_natural_ms = 0, voice_target_ms = 0, voice_delay_ms = 0;
  // Medians over the measured pictures: extra voice delay applied for sync
  // (target − natural, ≥ 0), picture hold for sync, and the picture's
  // capture → display delay.
  double voice_sync_delay_ms = 0, picture_sync_delay_ms = 0, picture_delay_ms = 0;
};

class AvSync {
 public:
  explicit AvSync(AvSyncOptions options = {});
  AvSync(const AvSync&) = delete;
  AvSync& operator=(const AvSync&) = delete;

  // A picture captured at `capture_us` is decoded and ready at `ready_us`.
  // Returns when to start rendering it: `ready_us` unless it must wait for
  // its voice (then later, at most max_picture_delay_ms later).
  int64_t PictureReady(int64_t capture_us, int64_t ready_us);
  // That picture was rendered from `render_start_us` and is visible from
  // `display_us` (a viewer that does not render passes its ready time for
  // both). Measures the av offset against every voice playing.
  void PictureDisplayed(int64_t capture_us, int64_t render_start_us, int64_t display_us);

  // One playout step of voice `stream`: the sample captured at `capture_us`
  // is heard at `playout_us`; `natural_delay_ms` is the capture → playout
  // delay this voice has without sync.
  void VoicePlayout(uint32_t stream, int64_t capture_us, int64_t playout_us, double natural_delay_ms);
  // The capture → playout delay the voices should have now, ms (0: no
  // constraint, play at the natural delay).
  double VoiceTargetMs(int64_t now_us);

  AvSyncStats stats() const;
  // The trace since the last ResetStats() (empty unless keep_trace).
  std::vector<AvSyncTracePoint> trace() const;
  // Forgets the measured offsets and counters (a measuring window starts);
  // the sync state stays.
  void ResetStats();
  const AvSyncOptions& options() const { return options_; }

 private:
  struct Voice {
    int64_t last_playout_us = 0;
    double delay_ms = 0;    // capture → playout at the last step
    double natural_ms = 0;
  };
  // Largest `delay` (&Voice::natural_ms or &Voice::delay_ms) of the voices
  // playing at `now_us`; < 0: none.
  double VoiceMaxLocked(double Voice::*delay, int64_t now_us) const;
  // pace_pictures: the natural delays' picture_quantile over the window
  // ending at now_us, ms (−1 without pictures).
  double PaceDelayLocked(int64_t now_us);
  // Drops the delay samples older than the window ending at now_us.
  void TrimWindowsLocked(int64_t now_us);
  void UpdateVoiceTargetLocked(int64_t now_us);

  AvSyncOptions options_;
  mutable std::mutex mu_;
  std::map<uint32_t, Voice> voices_;
  std::deque<std::pair<int64_t, double>> picture_delays_;  // (display time, capture → display ms)
  std::deque<std::pair<int64_t, double>> natural_delays_;  // (ready time, capture → ready + render ms)
  int64_t last_picture_us_ = 0;
  std::deque<double> render_ms_;                           // recent render durations
  std::map<int64_t, double> holds_;                        // capture → hold ms of pictures not yet displayed
  double voice_target_ms_ = 0;
  int64_t last_update_us_ = 0;
  bool updated_ = false;
  AvSyncStats n_;
  std::vector<float> offsets_, unsynced_, voice_sync_, picture_sync_, picture_delay_;
  std::vector<AvSyncTracePoint> trace_;
};

}  // namespace holo::audio
