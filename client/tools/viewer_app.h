// The holoport-client viewer loop: a source of stream frames, the renderer,
// the camera (orbit, interactive or a recorded head trace), the mosaic and
// miniature modes, the overlay, PNG and stats output.
#pragma once

#include <string>

#include <Eigen/Core>

#include "audio/av_sync.h"

namespace holo::client {

struct ViewerOptions {
  std::string source = "synthetic:S8-QVGA";
  bool headless = false;
  int frames = 0;  // 0: 30 headless, unlimited in a window
  std::string out_dir = "client-output";
  int width = 1280, height = 720;
  int views = 1;
  float view_spacing_m = 0.04f;
  float hfov_deg = 60.0f;
  float miniature_scale = 0.0f;  // 0 = off
  Eigen::Vector3f miniature_at = Eigen::Vector3f(0.0f, 0.0f, 0.75f);
  float miniature_yaw_deg = 0.0f;
  std::string pose_trace;  // CSV (time, x, y, z, yaw, pitch, roll); empty = orbit
  // "projective" (the pods' images blended once per mesh into an atlas),
  // "projective-fragment" (blended per pixel, with the view-dependent term)
  // or "vertex"
  std::string color = "projective";
  // "", "table", a PLY of the local site, or synthetic:WORKLOAD (the local
  // site's people, live from a second studio)
  std::string local;
  // Where the remote room goes in the local room (scale 1), e.g. facing the
  // local people in a two-site call: X, Y, Z, yaw; unset = identity.
  bool remote_placed = false;
  Eigen::Vector3f remote_at = Eigen::Vector3f::Zero();
  float remote_yaw_deg = 0.0f;
  bool see_through = false;          // local geometry occludes but is not drawn
  bool overlay = true;
  bool write_png = true;
  int threads = 2;
  // Network (docs/viewer.md "Connecting"): --connect HOST:PORT --token T
  // watches a site; --call CONFIG is one side of a two-site call (watch the
  // remote site, publish the own voice + head pose, spatialize the remote
  // voices into --audio-out). Either replaces --source.
  std::string connect;
  std::string token;
  // Play a live broadcast from an HTTP edge instead (docs/broadcast.md):
  // http://EDGE/NAME/live.json[?md5=…&expires=…].
  std::string http;
  std::string call;
  std::string name = "holoport-client";
  // Network: the quality cap sent to the site (Control set quality): 10 lets
  // the site choose the layer; 0..4 keep to its reduced layer.
  int quality = 10;
  // --call: where the participant's head stands in the own room (metres,
  // degrees; x forward at yaw 0), swaying a little; unset: net::SyntheticHead.
  bool head_placed = false;
  Eigen::Vector3f head_at = Eigen::Vector3f::Zero();
  float head_yaw_deg = 0.0f;
  std::string audio_in;   // --call: own voice (WAV); empty: a tone
  std::string audio_out;  // --call: spatialized stereo WAV of the remote voices; --connect/--http: the site's voices (mono)
  bool aec = false;       // --call: echo cancellation + noise suppression of the own voice
  int aec_filter_ms = 0;  // --call: its filter length, ms (0: the engine's default)
  std::string hrtf_sofa;  // --call: personal HRTF (SOFA); empty: OpenAL Soft's
  double seconds = 0;     // network: stop after this long (0: --frames decides)
  // Network: voice and picture in sync (audio/av_sync.h): the stream that
  // arrives first waits for the other, within these bounds (ms). Off: each
  // plays as soon as it can (offsets are still measured).
  audio::AvSyncOptions sync;
  // Test hooks: every voice frame / picture waits this long on arrival (ms).
  double delay_voice_ms = 0;
  double delay_picture_ms = 0;
  int png_every = 1;      // headless: write every K-th displayed frame
  double png_interval_s = 0;  // headless network run: a PNG every S seconds instead (0: png_every)
  bool contact_sheet = false;  // headless: also a contact sheet of the written frames
  double connect_timeout_s = 10;  // give up when no site answered within this (0: wait forever)
};

// Runs the viewer; prints progress and errors; returns the process exit code.
int RunViewer(const ViewerOptions& options);

}  // namespace holo::client
