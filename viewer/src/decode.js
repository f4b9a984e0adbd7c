// Decoding of the WebSocket messages of `sonoshape view` (docs/viewer.md): one message carries one
// multipart message of the mesh stream (docs/formats/mesh-stream.md) with its frames unchanged.
// No three.js here, so that node's test runner checks it as it is.

/** A message that breaks the format; `message` says which topic and what is wrong. */
export class DecodeError extends Error {}

const kMaxFrames = 16;
const utf8 = new TextDecoder('utf-8', { fatal: true });

/**
 * Splits one WebSocket message into its frames: a uint32 frame count, one uint32 byte length per
 * frame, then the frames, each padded to a multiple of 4 bytes (all little-endian).
 * @param {ArrayBuffer} buffer the message as received (binaryType 'arraybuffer')
 * @returns {Uint8Array[]} views into `buffer`, no copies
 * @throws {DecodeError} for a truncated message, a count out of range or trailing bytes
 */
export function unpackFrames(buffer) {
  const view = new DataView(buffer);
  if (buffer.byteLength < 4) throw new DecodeError('message of ' + buffer.byteLength + ' bytes');
  const count = view.getUint32(0, true);
  if (count < 1 || count > kMaxFrames) throw new DecodeError('frame count ' + count);
  let at = 4 + 4 * count;
  if (at > buffer.byteLength) throw new DecodeError('message shorter than its frame table');
  const frames = [];
  for (let i = 0; i < count; ++i) {
    const size = view.getUint32(4 + 4 * i, true);
    if (at + size > buffer.byteLength)
      throw new DecodeError('frame ' + i + ' of ' + size + ' bytes runs past the message');
    frames.push(new Uint8Array(buffer, at, size));
    at += Math.ceil(size / 4) * 4;
  }
  if (at !== buffer.byteLength) throw new DecodeError((buffer.byteLength - at) + ' bytes after the frames');
  return frames;
}

function isCount(value) {
  return Number.isInteger(value) && value >= 0;
}

// A typed array over a frame, in place: pack_frames aligns every frame to 4 bytes. The stream is
// little-endian, as is every platform a browser runs WebGL on.
function floats(frame, count) {
  return new Float32Array(frame.buffer, frame.byteOffset, count);
}

function decodeMesh(topic, header, frames) {
  const fail = (what) => {
    throw new DecodeError(topic + ' seq ' + header.seq + ': ' + what);
  };
  const label = Number(topic.slice(5));
  if (!/^[1-9][0-9]*$/.test(topic.slice(5))) fail('the topic names no label');
  if (header.label !== label) fail('header label ' + header.label + ' is not the topic\'s');
  const n = header.vertex_count;
  const m = header.triangle_count;
  if (!isCount(n) || !isCount(m)) fail('vertex_count and triangle_count must be counts');
  const normals = header.normals === true;
  if (frames.length !== (normals ? 5 : 4))
    fail(frames.length + ' frames, not ' + (normals ? 5 : 4));
  if (frames[2].byteLength !== 12 * n) fail('positions frame is not 12 * vertex_count bytes');
  if (frames[3].byteLength !== 12 * m) fail('indices frame is not 12 * triangle_count bytes');
  if (normals && frames[4].byteLength !== 12 * n) fail('normals frame is not 12 * vertex_count bytes');
  const positions = floats(frames[2], 3 * n);
  const indices = new Uint32Array(frames[3].buffer, frames[3].byteOffset, 3 * m);
  for (let i = 0; i < indices.length; ++i)
    if (indices[i] >= n) fail('vertex index ' + indices[i] + ' >= vertex_count ' + n);
  for (let i = 0; i < positions.length; ++i)
    if (!Number.isFinite(positions[i])) fail('non-finite position');
  return {
    kind: 'mesh', topic, header, label, name: String(header.name ?? ''),
    positions, indices, normals: normals ? floats(frames[4], 3 * n) : null,
  };
}

function isVec3(value) {
  return Array.isArray(value) && value.length === 3 && value.every(Number.isFinite);
}

// A plane as the stream writes it: {"origin", "u", "v"}, u and v unit and orthogonal (1e-6, as
// slices.md asks). Returned as plain arrays.
function decodePlane(plane, fail) {
  if (plane === null || typeof plane !== 'object' || Array.isArray(plane)) fail('"plane" is missing');
  for (const key of ['origin', 'u', 'v'])
    if (!isVec3(plane[key])) fail('"plane" ' + key + ' must be [x, y, z], finite');
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  if (Math.abs(dot(plane.u, plane.u) - 1) > 2e-6 || Math.abs(dot(plane.v, plane.v) - 1) > 2e-6 ||
      Math.abs(dot(plane.u, plane.v)) > 1e-6)
    fail('"plane" u and v must be unit and orthogonal');
  return { origin: plane.origin, u: plane.u, v: plane.v };
}

function isRing(ring) {
  return Array.isArray(ring) && ring.length >= 3 &&
    ring.every((p) => Array.isArray(p) && p.length === 2 && p.every(Number.isFinite));
}

function decodeSlice(topic, header, frames) {
  const fail = (what) => {
    throw new DecodeError(topic + ' seq ' + header.seq + ': ' + what);
  };
  if (frames.length !== 2) fail(frames.length + ' frames, not 2');
  if (!isCount(header.index)) fail('"index" must be a count');
  const plane = decodePlane(header.plane, fail);
  const fov = header.fov === undefined ? null : header.fov;
  if (fov !== null && !isRing(fov)) fail('"fov" must be a ring of [a, b] points');
  const regions = header.regions ?? [];
  if (!Array.isArray(regions) || !regions.every((r) => r && isRing(r.polygon)))
    fail('"regions" must be a list of regions with a "polygon"');
  return { kind: 'slice', topic, header, index: header.index, plane, fov, regions };
}

function decodeFrame(topic, header, frames) {
  const fail = (what) => {
    throw new DecodeError(topic + ' seq ' + header.seq + ': ' + what);
  };
  if (frames.length !== 3) fail(frames.length + ' frames, not 3');
  if (header.format !== 'gray8') fail('format ' + JSON.stringify(header.format) + ', not gray8');
  const { width, height } = header;
  if (!isCount(width) || !isCount(height) || width < 1 || height < 1 || width > 1024 || height > 1024)
    fail('width and height must be 1 to 1024 pixels');
  if (frames[2].byteLength !== width * height) fail('pixels frame is not width * height bytes');
  const plane = decodePlane(header.plane, fail);
  const size = header.size_mm;
  if (!Array.isArray(size) || size.length !== 2 || !size.every((x) => Number.isFinite(x) && x > 0))
    fail('"size_mm" must be [width, height] in mm, both > 0');
  return { kind: 'frame', topic, header, width, height, pixels: frames[2], plane, sizeMm: size };
}

/**
 * Decodes one WebSocket message.
 * @param {ArrayBuffer} buffer
 * @returns {{kind: 'mesh'|'slice'|'frame'|'status'|'viewer', topic: string, header: object}} and,
 *   for a mesh, `label`, `name`, `positions` (Float32Array, x y z in mm), `indices` (Uint32Array,
 *   three per triangle) and `normals` (Float32Array or null), all views into `buffer`; for a
 *   slice, `index`, `plane` ({origin, u, v} arrays, mm), `fov` ([a, b] points or null: the whole
 *   plane) and `regions`; for a frame, `width`, `height`, `pixels` (Uint8Array, row-major from
 *   the transducer side), `plane` and `sizeMm` ([width, height] of the picture in mm)
 * @throws {DecodeError} naming the topic and seq for anything the format does not allow
 */
export function decodeMessage(buffer) {
  const frames = unpackFrames(buffer);
  let topic;
  let header;
  try {
    topic = utf8.decode(frames[0]);
    if (frames.length < 2) throw new DecodeError(topic + ': no header frame');
    header = JSON.parse(utf8.decode(frames[1]));
  } catch (e) {
    if (e instanceof DecodeError) throw e;
    throw new DecodeError((topic ?? 'message') + ': header is not UTF-8 JSON (' + e.message + ')');
  }
  if (header === null || typeof header !== 'object' || Array.isArray(header))
    throw new DecodeError(topic + ': header is not a JSON object');
  if (topic === 'viewer') return { kind: 'viewer', topic, header };
  // Every stream header carries the version (a slice's plane is under "plane").
  if (header.v !== 1) throw new DecodeError(topic + ' seq ' + header.seq + ': version ' + JSON.stringify(header.v) + ', not 1');
  if (topic.startsWith('mesh.')) return decodeMesh(topic, header, frames);
  if (topic === 'slice') return decodeSlice(topic, header, frames);
  if (topic === 'frame') return decodeFrame(topic, header, frames);
  if (topic === 'status') {
    if (frames.length !== 2) throw new DecodeError('status seq ' + header.seq + ': ' + frames.length + ' frames, not 2');
    return { kind: 'status', topic, header };
  }
  throw new DecodeError('unknown topic ' + JSON.stringify(topic));
}
