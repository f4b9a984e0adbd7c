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

/**
 * Decodes one WebSocket message.
 * @param {ArrayBuffer} buffer
 * @returns {{kind: 'mesh'|'status'|'viewer', topic: string, header: object}} and, for a mesh,
 *   `label`, `name`, `positions` (Float32Array, x y z in mm), `indices` (Uint32Array, three per
 *   triangle) and `normals` (Float32Array or null), all views into `buffer`
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
  if (header.v !== 1) throw new DecodeError(topic + ' seq ' + header.seq + ': version ' + header.v + ', not 1');
  if (topic.startsWith('mesh.')) return decodeMesh(topic, header, frames);
  if (topic === 'status') {
    if (frames.length !== 2) throw new DecodeError('status seq ' + header.seq + ': ' + frames.length + ' frames, not 2');
    return { kind: 'status', topic, header };
  }
  throw new DecodeError('unknown topic ' + JSON.stringify(topic));
}
