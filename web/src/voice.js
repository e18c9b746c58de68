// The site's voice through Web Audio: every AudioPose's 20 ms are scheduled
// at their place on the playback clock through an HRTF PannerNode placed at
// the speaker's head (the pose of that AudioPose; room frame: Z up, head x
// forward), heard from the viewer's camera. PCM is played as it is; Opus
// through WebCodecs' AudioDecoder where the browser has it.

export class SpatialVoice {
  constructor() {
    this.enabled = false;
    this.ctx = null;
    this.panner = null;
    this.opus = null;
    this.nextOpusAt = 0;
  }

  enable() {
    if (this.enabled) return;
    const AC = globalThis.AudioContext || globalThis.webkitAudioContext;
    if (!AC) return;
    this.ctx = new AC({ latencyHint: 'interactive' });
    this.panner = new PannerNode(this.ctx, {
      panningModel: 'HRTF', distanceModel: 'inverse', refDistance: 1, rolloffFactor: 1,
      coneInnerAngle: 360, coneOuterAngle: 360,
    });
    this.panner.connect(this.ctx.destination);
    this.ctx.resume();
    this.enabled = true;
  }

  // Room (Z up) → Web Audio (Y up): (x, y, z) → (x, z, −y).
  static toAudio(x, y, z) {
    return [x, z, -y];
  }

  // `a`: a parsed AudioPose; `aheadUs`: how far its start lies ahead of the
  // playhead now.
  push(a, aheadUs) {
    if (!this.enabled || this.ctx.state === 'closed') return;
    const when = this.ctx.currentTime + Math.max(0, aheadUs) / 1e6 + 0.02;
    const [px, py, pz] = SpatialVoice.toAudio(a.pose.x, a.pose.y, a.pose.z);
    const fx = Math.cos(a.pose.yaw) * Math.cos(a.pose.pitch), fy = Math.sin(a.pose.yaw) * Math.cos(a.pose.pitch);
    const fz = Math.sin(a.pose.pitch);
    const [ox, oy, oz] = SpatialVoice.toAudio(fx, fy, fz);
    const p = this.panner;
    // What was scheduled (for tests and the overlay): the last few positions.
    this.scheduled = (this.scheduled || []).slice(-200);
    this.scheduled.push({ when, pos: [px, py, pz], pose: a.pose });
    p.positionX.setValueAtTime(px, when);
    p.positionY.setValueAtTime(py, when);
    p.positionZ.setValueAtTime(pz, when);
    p.orientationX.setValueAtTime(ox, when);
    p.orientationY.setValueAtTime(oy, when);
    p.orientationZ.setValueAtTime(oz, when);
    if (a.codec === 1) {
      const n = a.audio.length / (2 * a.channels);
      const buf = this.ctx.createBuffer(a.channels, n, a.sampleRate);
      const dv = new DataView(a.audio.buffer, a.audio.byteOffset, a.audio.byteLength);
      for (let c = 0; c < a.channels; ++c) {
        const ch = buf.getChannelData(c);
        for (let i = 0; i < n; ++i) ch[i] = dv.getInt16(2 * (i * a.channels + c), true) / 32768;
      }
      this.play(buf, when);
    } else if ((a.codec === 2 || a.codec === 3) && globalThis.AudioDecoder) {  // classic or lean Opus frame
      this.decodeOpus(a, when);
    }
  }

  play(buf, when) {
    const s = this.ctx.createBufferSource();
    s.buffer = buf;
    s.connect(this.panner);
    s.start(when);
  }

  decodeOpus(a, when) {
    if (!this.opus || this.opusRate !== a.sampleRate || this.opusChannels !== a.channels) {
      this.opusRate = a.sampleRate;
      this.opusChannels = a.channels;
      this.opusWhen = [];
      this.opus = new AudioDecoder({
        output: (data) => {
          const at = this.opusWhen.shift() ?? this.ctx.currentTime;
          const buf = this.ctx.createBuffer(data.numberOfChannels, data.numberOfFrames, data.sampleRate);
          for (let c = 0; c < data.numberOfChannels; ++c) {
            data.copyTo(buf.getChannelData(c), { planeIndex: c, format: 'f32-planar' });
          }
          data.close();
          this.play(buf, Math.max(at, this.ctx.currentTime));
        },
        error: () => { this.opus = null; },
      });
      this.opus.configure({ codec: 'opus', sampleRate: a.sampleRate, numberOfChannels: a.channels });
    }
    this.opusWhen.push(when);
    this.opus.decode(new EncodedAudioChunk({ type: 'key', timestamp: a.captureUs, data: a.audio }));
  }

  // The listener at the viewer's camera (three.js world = room, Z up, unless
  // in XR where the content is turned Y up and three's frame is Web Audio's).
  setListener(camera, yUp) {
    if (!this.enabled) return;
    const e = camera.matrixWorld.elements;
    const pos = [e[12], e[13], e[14]], fwd = [-e[8], -e[9], -e[10]], up = [e[4], e[5], e[6]];
    const conv = yUp ? (v) => v : (v) => SpatialVoice.toAudio(v[0], v[1], v[2]);
    const [px, py, pz] = conv(pos), [fx, fy, fz] = conv(fwd), [ux, uy, uz] = conv(up);
    const l = this.ctx.listener, t = this.ctx.currentTime;
    if (l.positionX) {
      l.positionX.setValueAtTime(px, t);
      l.positionY.setValueAtTime(py, t);
      l.positionZ.setValueAtTime(pz, t);
      l.forwardX.setValueAtTime(fx, t);
      l.forwardY.setValueAtTime(fy, t);
      l.forwardZ.setValueAtTime(fz, t);
      l.upX.setValueAtTime(ux, t);
      l.upY.setValueAtTime(uy, t);
      l.upZ.setValueAtTime(uz, t);
    } else {
      l.setPosition(px, py, pz);
      l.setOrientation(fx, fy, fz, ux, uy, uz);
    }
  }
}
