// Protocol messages (protocol/PROTOCOL.md) and the message records of the
// recording container / live parts (docs/recording.md §1, docs/broadcast.md
// §2). Safe on untrusted input: DecodeError naming the field.

import { Reader, fail, crc32c } from './bytes.js';

export const MSG = { RIG: 4, MESH: 5, COLOR: 6, AUDIO: 7, STATS: 13 };
export const HEADER_BYTES = 32;
export const RECORD_HEADER_BYTES = 24;
export const MAX_MESSAGE_BYTES = 64 << 20;
const HLPT = 0x54504c48, HLRM = 0x4d524c48, HLRC = 0x43524c48;

export function parseHeader(bytes) {
  const r = new Reader(bytes);
  const magic = r.u32('header.magic');
  if (magic !== HLPT) fail('header.magic: not a Holoport frame');
  const version = r.u16('header.version');
  if (version !== 1) fail(`header.version: peer speaks protocol version ${version}, this viewer speaks 1`);
  const type = r.u16('header.type');
  const flags = r.u16('header.flags');
  if (flags & ~3) fail('header.flags: reserved bits set');
  if (r.u16('header.reserved') !== 0) fail('header.reserved: must be zero');
  const stream = r.u32('header.stream_id');
  const sequence = r.u32('header.sequence');
  const captureUs = r.i64('header.capture_time_us');
  const length = r.u32('header.payload_length');
  return { type, flags, stream, sequence, captureUs, length, keyFrame: (flags & 2) !== 0 };
}

// Splits a run of message records (a live part, or a recording's records
// from `offset`) into messages: [{timeUs, header, payload}]. With `whole`
// the bytes must end exactly at a record end; a recording's index/end
// records stop the scan.
export function parseRecords(bytes, offset = 0, { whole = true } = {}) {
  const out = [];
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  let p = offset;
  let lastTime = -1;
  while (p < bytes.length) {
    if (bytes.length - p < RECORD_HEADER_BYTES) fail(`record at ${p}: truncated header`);
    if (dv.getUint32(p, true) !== HLRM) fail(`record at ${p}: bad magic`);
    const kind = bytes[p + 4];
    if (bytes[p + 5] || bytes[p + 6] || bytes[p + 7]) fail(`record at ${p}: reserved bytes set`);
    const len = dv.getUint32(p + 8, true);
    if (kind === 2 || kind === 3) {
      if (whole) fail(`record at ${p}: index/end record in a part`);
      break;
    }
    if (kind !== 1) fail(`record at ${p}: unknown kind ${kind}`);
    if (len < HEADER_BYTES || len > MAX_MESSAGE_BYTES + HEADER_BYTES) fail(`record at ${p}: body length ${len} out of range`);
    if (len > bytes.length - p - RECORD_HEADER_BYTES) fail(`record at ${p}: body truncated`);
    const crc = dv.getUint32(p + 12, true);
    let c = crc32c(bytes.subarray(p, p + 12));
    c = crc32c(bytes.subarray(p + 16, p + 24), c);
    c = crc32c(bytes.subarray(p + 24, p + 24 + len), c);
    if (c !== crc) fail(`record at ${p}: CRC mismatch`);
    const t = dv.getBigInt64(p + 16, true);
    if (t < 0n || t > BigInt(Number.MAX_SAFE_INTEGER)) fail(`record at ${p}: time out of range`);
    const timeUs = Number(t);
    if (timeUs < lastTime) fail(`record at ${p}: time goes backwards`);
    lastTime = timeUs;
    const body = bytes.subarray(p + 24, p + 24 + len);
    const header = parseHeader(body);
    if (header.length !== len - HEADER_BYTES) fail(`record at ${p}: payload length ${header.length} != body − 32`);
    if (header.flags & 1) fail(`record at ${p}: MORE_FRAGMENTS set in a record`);
    out.push({ timeUs, header, payload: body.subarray(HEADER_BYTES), offset: p });
    p += 24 + len;
  }
  return out;
}

// A whole recording file (or segment): checks the file header, returns its
// messages.
export function parseRecording(bytes) {
  const r = new Reader(bytes);
  if (r.u32('file.magic') !== HLRC) fail('file.magic: not a Holoport recording');
  const fv = r.u16('file.format_version');
  if (fv !== 1) fail(`file.format_version: ${fv} unsupported`);
  if (r.u16('file.header_size') !== 64) fail('file.header_size: must be 64');
  const crc = new DataView(bytes.buffer, bytes.byteOffset + 60, 4).getUint32(0, true);
  if (crc32c(bytes.subarray(0, 60)) !== crc) fail('file.crc: header CRC mismatch');
  return parseRecords(bytes, 64, { whole: false });
}

function readIntrinsics(r, field) {
  const width = r.u32(field), height = r.u32(field);
  if (width < 1 || height < 1 || width > 8192 || height > 8192) fail(`${field}: image size ${width}x${height} outside 1..8192`);
  const fx = r.f64(field), fy = r.f64(field), cx = r.f64(field), cy = r.f64(field);
  const distortion = [r.f64(field), r.f64(field), r.f64(field), r.f64(field), r.f64(field)];
  if (!(fx > 0) || !(fy > 0)) fail(`${field}: focal length must be > 0`);
  return { width, height, fx, fy, cx, cy, distortion };
}

// pose34 → { R: [9] row-major, t: [3] }.
function readPose(r, field) {
  const R = [];
  for (let i = 0; i < 9; ++i) R.push(r.f32(field));
  const t = [r.f32(field), r.f32(field), r.f32(field)];
  for (let i = 0; i < 3; ++i)
    for (let j = 0; j < 3; ++j) {
      let d = 0;
      for (let k = 0; k < 3; ++k) d += R[3 * k + i] * R[3 * k + j];
      if (Math.abs(d - (i === j ? 1 : 0)) > 1e-3) fail(`${field}: rotation is not orthonormal`);
    }
  const det = R[0] * (R[4] * R[8] - R[5] * R[7]) - R[1] * (R[3] * R[8] - R[5] * R[6]) + R[2] * (R[3] * R[7] - R[4] * R[6]);
  if (det < 0.5) fail(`${field}: rotation is not orthonormal`);
  return { R, t };
}

export function parseRig(payload) {
  const r = new Reader(payload);
  const name = r.str16('rig.name');
  const n = r.u16('rig.num_pods');
  if (n > 64) fail(`rig.num_pods: ${n} exceeds limit 64`);
  if (n > r.remaining() / 262) fail('rig.num_pods: count exceeds the payload');
  const pods = [];
  for (let i = 0; i < n; ++i) {
    const id = r.i32('rig.pod.id');
    const podName = r.str16('rig.pod.name');
    const depth = readIntrinsics(r, 'rig.pod.depth');
    const color = readIntrinsics(r, 'rig.pod.color');
    const colorFromDepth = readPose(r, 'rig.pod.color_from_depth');
    const worldFromDepth = readPose(r, 'rig.pod.world_from_depth');
    pods.push({ id, name: podName, depth, color, colorFromDepth, worldFromDepth });
  }
  r.expectEnd('rig');
  return { name, pods };
}

export function parseMeshFrame(payload) {
  const r = new Reader(payload);
  const frameIndex = r.i64('mesh_frame.frame_index');
  const codec = r.u8('mesh_frame.codec');
  // G0, G1, G3 (the native reader's set: G2 is not sent on this path).
  if (codec < 1 || codec > 4 || codec === 3) fail(`mesh_frame.codec: unknown geometry codec ${codec}`);
  const data = r.blob32('mesh_frame.data');
  r.expectEnd('mesh_frame');
  return { frameIndex, codec, data };
}

export function parseColorFrame(payload) {
  const r = new Reader(payload);
  const frameIndex = r.i64('color_frame.frame_index');
  const codec = r.u8('color_frame.codec');
  if (codec < 1 || codec > 4) fail(`color_frame.codec: unknown colour codec ${codec}`);
  const n = r.u8('color_frame.num_images');
  if (n > 64) fail(`color_frame.num_images: ${n} exceeds limit 64`);
  const images = [];
  for (let i = 0; i < n; ++i) {
    const podId = r.u16('color_frame.pod_id');
    images.push({ podId, data: r.blob32('color_frame.image') });
  }
  r.expectEnd('color_frame');
  return { frameIndex, codec, images };
}

// Lean AudioPose (codec 3, PROTOCOL.md §9.1): sequence and capture time are
// the header's; position in mm (i16, or i32 with flag 2), angles in steps of
// 2π/65536 rad; the Opus packet is the rest of the payload (1..1275 bytes).
// Without a pose (flag 1 clear) `pose` is null: the caller keeps the last one.
const LEAN_ANGLE_STEP = 2 * Math.PI / 65536;
function parseLeanAudioPose(r, header) {
  if (!header) fail('audio_pose: a lean frame (codec 3) needs its message header');
  const flags = r.u8('audio_pose.lean_flags');
  if (flags & ~3) fail('audio_pose.lean_flags: unknown flag bits set');
  const hasPose = (flags & 1) !== 0, wide = (flags & 2) !== 0;
  if (wide && !hasPose) fail('audio_pose.lean_flags: wide position without a pose');
  let pose = null;
  if (hasPose) {
    const mm = [];
    for (let i = 0; i < 3; ++i) {
      if (wide) {
        const v = r.i32('audio_pose.lean_position');
        if (v > 1000000 || v < -1000000) fail('audio_pose.lean_position: beyond ±1 km');
        mm.push(v);
      } else {
        const u = r.u16('audio_pose.lean_position');
        mm.push(u >= 32768 ? u - 65536 : u);
      }
    }
    const ang = [];
    for (let i = 0; i < 3; ++i) {
      const u = r.u16('audio_pose.lean_angle');
      ang.push((u >= 32768 ? u - 65536 : u) * LEAN_ANGLE_STEP);
    }
    pose = { x: mm[0] / 1000, y: mm[1] / 1000, z: mm[2] / 1000, yaw: ang[0], pitch: ang[1], roll: ang[2] };
  }
  const n = r.remaining();
  if (n === 0) fail('audio_pose.audio: lean frame without an Opus packet');
  if (n > 1275) fail(`audio_pose.audio: lean frame's Opus packet of ${n} bytes exceeds 1275`);
  const audio = r.bytesView(n, 'audio_pose.audio');
  return { codec: 3, channels: 1, durationUs: 20000, sampleRate: 48000, sequence: header.sequence,
    captureUs: header.captureUs, pose, hasPose, audio };
}

// `header` (parseHeader's) is needed for lean frames (codec 3).
export function parseAudioPose(payload, header = null) {
  const r = new Reader(payload);
  const codec = r.u8('audio_pose.codec');
  if (codec < 1 || codec > 3) fail(`audio_pose.codec: unknown audio codec ${codec}`);
  if (codec === 3) return parseLeanAudioPose(r, header);
  const channels = r.u8('audio_pose.channels');
  if (channels < 1 || channels > 2) fail(`audio_pose.channels: must be 1 or 2, got ${channels}`);
  const duration = r.u16('audio_pose.duration');
  if (duration === 0) fail('audio_pose.duration: must be > 0');
  const sampleRate = r.u32('audio_pose.sample_rate');
  if (sampleRate < 8000 || sampleRate > 192000) fail(`audio_pose.sample_rate: ${sampleRate} outside 8000..192000`);
  const sequence = r.u32('audio_pose.sequence');
  const captureUs = r.i64('audio_pose.capture_time_us');
  const pose = { x: r.f32('audio_pose.pose'), y: r.f32('audio_pose.pose'), z: r.f32('audio_pose.pose'),
    yaw: r.f32('audio_pose.pose'), pitch: r.f32('audio_pose.pose'), roll: r.f32('audio_pose.pose') };
  const n = r.u16('audio_pose.audio');
  const audio = r.bytesView(n, 'audio_pose.audio');
  r.expectEnd('audio_pose');
  if (codec === 1 && n !== Math.round(duration * 10 * sampleRate / 1e6) * channels * 2) {
    fail(`audio_pose.audio: ${n} PCM bytes do not match the duration`);
  }
  return { codec, channels, durationUs: duration * 10, sampleRate, sequence, captureUs, pose, hasPose: true, audio };
}
