// The page's decoding of `sonoshape view` messages (docs/viewer.md, docs/formats/mesh-stream.md):
// messages are built here byte by byte as the server packs them.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { decodeMessage, unpackFrames, DecodeError } from '../src/decode.js';
import { labelColor } from '../src/palette.js';

const encoder = new TextEncoder();

// As pack_frames in publish/src/view_server.cpp: count, lengths, frames padded to 4 bytes.
function pack(frames) {
  const bytes = frames.map((f) => (typeof f === 'string' ? encoder.encode(f) : new Uint8Array(f.buffer, f.byteOffset, f.byteLength)));
  const padded = bytes.map((b) => Math.ceil(b.byteLength / 4) * 4);
  const buffer = new ArrayBuffer(4 + 4 * bytes.length + padded.reduce((a, b) => a + b, 0));
  const view = new DataView(buffer);
  view.setUint32(0, bytes.length, true);
  bytes.forEach((b, i) => view.setUint32(4 + 4 * i, b.byteLength, true));
  let at = 4 + 4 * bytes.length;
  bytes.forEach((b, i) => {
    new Uint8Array(buffer, at, b.byteLength).set(b);
    at += padded[i];
  });
  return buffer;
}

function meshHeader(fields = {}) {
  return JSON.stringify({
    v: 1, seq: 7, scan: 'a1', label: 2, name: 'kidney', units: 'mm', frame: 'reference',
    timestamp_s: 1.5, slices: 4, vertex_count: 4, triangle_count: 2,
    bounds: { min: [0, 0, 0], max: [1, 1, 1] }, ...fields,
  });
}

const positions = new Float32Array([0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]);
const indices = new Uint32Array([0, 2, 1, 1, 2, 3]);

test('a mesh message decodes to views of its positions and indices', () => {
  const message = decodeMessage(pack(['mesh.2', meshHeader(), positions, indices]));
  assert.equal(message.kind, 'mesh');
  assert.equal(message.label, 2);
  assert.equal(message.name, 'kidney');
  assert.equal(message.header.seq, 7);
  assert.deepEqual([...message.positions], [...positions]);
  assert.deepEqual([...message.indices], [...indices]);
  assert.equal(message.normals, null);
});

test('frames land on 4-byte boundaries whatever the header length', () => {
  for (const name of ['k', 'ki', 'kid', 'kidn']) {
    const message = decodeMessage(pack(['mesh.2', meshHeader({ name }), positions, indices]));
    assert.equal(message.positions.byteOffset % 4, 0);
    assert.equal(message.name, name);
  }
});

test('normals come with a fifth frame when the header says so', () => {
  const normals = new Float32Array(12).fill(0.5);
  const message = decodeMessage(pack(['mesh.2', meshHeader({ normals: true }), positions, indices, normals]));
  assert.deepEqual([...message.normals], [...normals]);
  assert.throws(() => decodeMessage(pack(['mesh.2', meshHeader({ normals: true }), positions, indices])),
                /5/);
});

test('an empty mesh (a vanished material) decodes with no triangles', () => {
  const message = decodeMessage(pack(['mesh.3', meshHeader({ label: 3, vertex_count: 0, triangle_count: 0, bounds: null }),
                                      new Float32Array(0), new Uint32Array(0)]));
  assert.equal(message.indices.length, 0);
  assert.equal(message.positions.length, 0);
});

test('status and viewer messages carry their headers', () => {
  const status = decodeMessage(pack(['status', JSON.stringify({ v: 1, seq: 9, scan: 'a1', frames_received: 120,
    frames_dropped: 3, slices: 11, total_ms: 42.5, state: 'scanning' })]));
  assert.equal(status.kind, 'status');
  assert.equal(status.header.frames_dropped, 3);
  const viewer = decodeMessage(pack(['viewer', JSON.stringify({ stream: 'waiting', endpoint: 'tcp://x:1' })]));
  assert.equal(viewer.kind, 'viewer');
  assert.equal(viewer.header.stream, 'waiting');
});

function sliceHeader(fields = {}) {
  return JSON.stringify({
    v: 1, seq: 12, scan: 'a1', index: 4,
    plane: { origin: [1.5, -2, 12.25], u: [0, 1, 0], v: [0, 0, 1] }, timestamp: 0.5,
    fov: [[-40, 0], [40, 0], [40, 60], [-40, 60]],
    regions: [{ label: 1, polygon: [[-10, 5], [12, 5], [12, 30]] }], ...fields,
  });
}

function frameHeader(fields = {}) {
  return JSON.stringify({
    v: 1, seq: 13, scan: 'a1', index: 31, timestamp_s: 1.25, format: 'gray8', width: 3, height: 2,
    plane: { origin: [-20, 0, 5], u: [1, 0, 0], v: [0, 0, -1] }, size_mm: [40, 30], ...fields,
  });
}

const pixels = new Uint8Array([0, 50, 100, 150, 200, 255]);

test('a slice message carries the version and its plane under "plane"', () => {
  const slice = decodeMessage(pack(['slice', sliceHeader()]));
  assert.equal(slice.kind, 'slice');
  assert.equal(slice.index, 4);
  assert.deepEqual(slice.plane, { origin: [1.5, -2, 12.25], u: [0, 1, 0], v: [0, 0, 1] });
  assert.equal(slice.fov.length, 4);
  assert.equal(slice.regions.length, 1);
  const wholePlane = decodeMessage(pack(['slice', sliceHeader({ fov: undefined })]));
  assert.equal(wholePlane.fov, null);
});

test('a frame message is a grey picture on its plane', () => {
  const frame = decodeMessage(pack(['frame', frameHeader(), pixels]));
  assert.equal(frame.kind, 'frame');
  assert.equal(frame.width, 3);
  assert.equal(frame.height, 2);
  assert.deepEqual([...frame.pixels], [...pixels]);
  assert.deepEqual(frame.sizeMm, [40, 30]);
  assert.deepEqual(frame.plane.v, [0, 0, -1]);
});

test('messages that break the format are refused, naming topic and problem', () => {
  const cases = [
    [pack(['mesh.2', meshHeader({ vertex_count: 5 }), positions, indices]), /mesh.2 seq 7: positions frame/],
    [pack(['mesh.2', meshHeader({ triangle_count: 1 }), positions, indices]), /indices frame/],
    [pack(['mesh.2', meshHeader({ label: 1 }), positions, indices]), /not the topic/],
    [pack(['mesh.2', meshHeader({ v: 2 }), positions, indices]), /version 2/],
    [pack(['mesh.2', meshHeader(), positions, new Uint32Array([0, 1, 4, 0, 1, 2])]), /index 4 >= vertex_count 4/],
    [pack(['mesh.2', meshHeader(), new Float32Array([NaN, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]), indices]), /non-finite/],
    [pack(['mesh.02', meshHeader(), positions, indices]), /no label/],
    [pack(['mesh.2', meshHeader(), positions]), /3 frames/],
    [pack(['mesh.2', '[1,2]', positions, indices]), /not a JSON object/],
    [pack(['mesh.2', '{"v":1', positions, indices]), /not UTF-8 JSON/],
    [pack(['slice', JSON.stringify({ seq: 3 })]), /version undefined/],
    // The old slice header: its plane at the top level, "v" a direction, not the version.
    [pack(['slice', JSON.stringify({ seq: 3, origin: [0, 0, 0], u: [1, 0, 0], v: [0, 1, 0] })]),
     /slice seq 3: version \[0,1,0\], not 1/],
    [pack(['slice', sliceHeader({ plane: undefined })]), /slice seq 12: "plane" is missing/],
    [pack(['slice', sliceHeader({ plane: { origin: [0, 0, 0], u: [2, 0, 0], v: [0, 1, 0] } })]),
     /unit and orthogonal/],
    [pack(['slice', sliceHeader({ fov: [[0, 0], [1, 1]] })]), /"fov" must be a ring/],
    [pack(['frame', frameHeader(), pixels.subarray(0, 5)]), /frame seq 13: pixels frame/],
    [pack(['frame', frameHeader({ format: 'rgb8' }), pixels]), /not gray8/],
    [pack(['frame', frameHeader({ size_mm: [40, 0] }), pixels]), /size_mm/],
    [pack(['frame', frameHeader()]), /2 frames, not 3/],
    [pack(['nonsense', JSON.stringify({ v: 1, seq: 3 })]), /unknown topic "nonsense"/],
    [pack(['status', JSON.stringify({ v: 1, seq: 3 }), 'extra']), /3 frames, not 2/],
  ];
  for (const [buffer, pattern] of cases)
    assert.throws(() => decodeMessage(buffer), (e) => e instanceof DecodeError && pattern.test(e.message),
                  String(pattern));
});

test('a truncated or padded-wrong message is refused before anything is read', () => {
  const good = pack(['status', JSON.stringify({ v: 1, seq: 1 })]);
  assert.throws(() => unpackFrames(good.slice(0, good.byteLength - 4)), DecodeError);
  assert.throws(() => unpackFrames(new ArrayBuffer(2)), DecodeError);
  const extra = new Uint8Array(good.byteLength + 4);
  extra.set(new Uint8Array(good));
  assert.throws(() => unpackFrames(extra.buffer), /4 bytes after the frames/);
  const zero = new ArrayBuffer(4);
  assert.throws(() => unpackFrames(zero), /frame count 0/);
});

test('labels have distinct, stable colours', () => {
  const colors = Array.from({ length: 12 }, (_, i) => labelColor(i + 1));
  assert.equal(new Set(colors).size, colors.length);
  for (const c of colors) assert.match(c, /^#[0-9a-f]{6}$/);
  assert.equal(labelColor(1), '#e4572e');
});
