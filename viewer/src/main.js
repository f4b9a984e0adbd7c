// The page: a WebSocket to `sonoshape view`, decoded messages to the scene, legend and status.
import { decodeMessage, DecodeError } from './decode.js';
import { labelColor } from './palette.js';
import { rampCss } from './coverage.js';
import { SceneView } from './scene.js';

const $ = (id) => document.getElementById(id);
const view = new SceneView($('scene'));
const labels = new Map();  // label -> { name, triangles, row }
let scan = null;
let lastMessageAt = 0;
let retryDelayMs = 500;
let everConnected = false;
// The last status of the scan shown (`"finished": true`) and what the page says of it: a server
// that goes after it has ended normally, not lost.
let finished = null;

// For tests and scripts: what the page has drawn so far.
window.sonoshapeViewer = {
  labelsDrawn: 0, messages: 0, rendered: 0, scan: null, slicesDrawn: 0, framesShown: 0,
  finished: false,
  coverage: null,  // the last distance colouring: vertices and milliseconds
};
window.sonoshapeViewer.gpu = { name: view.gpu, antialias: view.antialias };
view.onRendered = () => {
  window.sonoshapeViewer.rendered += 1;
  noteDrawn();
};
view.onCoverage = (c) => { window.sonoshapeViewer.coverage = c; };

function say(text, kind = 'info') {
  const line = $('connection');
  line.textContent = text;
  line.className = kind;
}

function legendRow(label, name) {
  const row = document.createElement('li');
  const color = labelColor(label);
  row.innerHTML =
    '<input type="checkbox" checked title="show or hide">' +
    '<span class="swatch"></span><span class="name"></span><span class="count"></span>' +
    '<input type="range" min="0" max="1" step="0.05" value="1" title="opacity">' +
    '<span class="downloads"><button data-format="ply" title="download the surface (mm)">PLY</button>' +
    '<button data-format="stl" title="download the surface (mm)">STL</button></span>';
  row.querySelector('.swatch').style.background = color;
  row.querySelector('.name').textContent = name || 'label ' + label;
  const [visible, opacity] = row.querySelectorAll('input');
  visible.addEventListener('change', () => view.setVisible(label, visible.checked));
  opacity.addEventListener('input', () => view.setOpacity(label, Number(opacity.value)));
  for (const button of row.querySelectorAll('button[data-format]'))
    button.addEventListener('click', () => downloadMesh(label, button.dataset.format));
  $('legend').appendChild(row);
  return row;
}

function download(url, filename) {
  const link = document.createElement('a');
  link.href = url;
  link.download = filename;
  link.click();
}

function fileStem(label) {
  const name = labels.get(label)?.row.querySelector('.name').textContent ?? '';
  return 'label_' + label + (name ? '_' + name.replace(/[^A-Za-z0-9_-]+/g, '_') : '');
}

function downloadMesh(label, format) {
  const bytes = view.exportMesh(label, format);
  if (!bytes) return say('label ' + label + ' has no surface yet', 'warn');
  const url = URL.createObjectURL(new Blob([bytes], { type: 'application/octet-stream' }));
  download(url, fileStem(label) + '.' + format);
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

// For bench/viewer_bench.mjs: when each mesh was drawn. A script sets `drawLog` to an array; the
// page then waits for each picture to be finished (a one-pixel read) and appends
// {label, seq, timestamp_s, received_ms, drawn_ms} (Unix times in ms) for every mesh it holds.
let undrawn = [];
function noteDrawn() {
  const log = window.sonoshapeViewer.drawLog;
  if (!Array.isArray(log) || !undrawn.length) return;
  view.finishDrawing();
  const drawnMs = performance.timeOrigin + performance.now();
  for (const entry of undrawn) log.push({ ...entry, drawn_ms: drawnMs });
  undrawn = [];
}

function showMesh(message, receivedMs) {
  if (Array.isArray(window.sonoshapeViewer.drawLog))
    undrawn.push({ label: message.label, seq: message.header.seq,
                   timestamp_s: message.header.timestamp_s, received_ms: receivedMs });
  let entry = labels.get(message.label);
  if (!entry) {
    entry = { row: legendRow(message.label, message.name) };
    labels.set(message.label, entry);
    // Keep the legend in label order.
    [...labels.keys()].sort((a, b) => a - b).forEach((l) => $('legend').appendChild(labels.get(l).row));
  }
  const triangles = message.indices.length / 3;
  entry.row.querySelector('.name').textContent = message.name || 'label ' + message.label;
  entry.row.querySelector('.count').textContent =
    triangles ? triangles.toLocaleString('en') + ' triangles' : 'none yet';
  view.setMesh(message.label, labelColor(message.label), message.positions, message.indices,
               message.normals);
  window.sonoshapeViewer.labelsDrawn = [...labels.keys()].length;
}

function showSlice(message) {
  view.addSlice(message);
  window.sonoshapeViewer.slicesDrawn = view.slices.length;
  $('planes').textContent = view.slices.length;
}

function showFrame(message) {
  view.setFrame(message);
  window.sonoshapeViewer.framesShown += 1;
}

// Milliseconds as the status shows them: '–' until the scan has said.
const ms = (value) => (Number.isFinite(value) ? Number(value).toFixed(0) : '–');

function showStatus(header) {
  const state = header.finished === true ? 'finished' : header.state;
  $('state').textContent = state + (header.message ? ': ' + header.message : '');
  $('state').className = state;
  $('frames').textContent = header.frames_received ?? '–';
  $('dropped').textContent = header.frames_dropped ?? '–';
  $('slices').textContent = header.slices ?? '–';
  $('update-ms').textContent = ms(header.update_ms ?? header.total_ms);
  $('latency-ms').textContent = ms(header.latency_ms);
  // A scan that publishes no frames says so (frame_rate_hz 0): the box is not a broken view.
  $('frame-hint').hidden = header.frame_rate_hz !== 0;
  if (header.finished === true) {
    finished = 'the scan finished: ' + header.slices + ' slices, ' + header.frames_received +
      ' frames in (' + header.frames_dropped + ' dropped); the surfaces shown are its result';
    window.sonoshapeViewer.finished = true;
    say(finished, 'ok');
  }
}

function followScan(header) {
  if (header.scan === scan) return;
  if (scan !== null) {
    say('a new scan began (' + header.scan.slice(0, 8) + '): its surfaces replace the old ones', 'info');
    view.clear();
    labels.clear();
    $('legend').replaceChildren();
    $('planes').textContent = '0';
    window.sonoshapeViewer.slicesDrawn = 0;
  }
  scan = header.scan;
  finished = null;
  window.sonoshapeViewer.finished = false;
  window.sonoshapeViewer.scan = scan;
  $('scan').textContent = scan.slice(0, 8);
}

function onMessage(event) {
  const receivedMs = performance.timeOrigin + performance.now();
  let message;
  try {
    message = decodeMessage(event.data);
  } catch (e) {
    if (!(e instanceof DecodeError)) throw e;
    console.warn('sonoshape viewer: skipped a message:', e.message);
    return;
  }
  lastMessageAt = performance.now();
  window.sonoshapeViewer.messages += 1;
  if (message.kind === 'viewer') {
    const h = message.header;
    if (h.stream === 'connected') say(finished ?? 'following the scan at ' + h.endpoint, 'ok');
    else if (h.stream === 'finished') say(h.message, 'ok');  // the scan's end, its counts
    else say('waiting for a scan at ' + h.endpoint + (h.message ? ': ' + h.message : ''), 'warn');
    return;
  }
  followScan(message.header);
  if (message.kind === 'mesh') showMesh(message, receivedMs);
  else if (message.kind === 'slice') showSlice(message);
  else if (message.kind === 'frame') showFrame(message);
  else showStatus(message.header);
}

function connect() {
  const socket = new WebSocket((location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/stream');
  socket.binaryType = 'arraybuffer';
  socket.addEventListener('open', () => {
    retryDelayMs = 500;
    say(everConnected ? 'reconnected to sonoshape' : 'connected to sonoshape', 'ok');
    everConnected = true;
  });
  socket.addEventListener('message', onMessage);
  socket.addEventListener('close', () => {
    const seconds = (retryDelayMs / 1000).toFixed(1);
    // After the scan's last status the server going is the normal end (scan --view exits with
    // its scan): the result stays; "lost" is only for a stream that ends without it.
    if (finished)
      say(finished + '. sonoshape has stopped serving this page (scan --view ends with its ' +
          'scan; --view-hold keeps serving it); this page keeps the result', 'ok');
    else
      say((everConnected ? 'lost sonoshape' : 'cannot reach sonoshape') + ' at ' + location.host +
          '; trying again in ' + seconds + ' s', 'error');
    setTimeout(connect, retryDelayMs);
    retryDelayMs = Math.min(retryDelayMs * 2, 5000);
  });
}

// How long since the stream last said anything: a stalled scan shows.
setInterval(() => {
  $('age').textContent = lastMessageAt ? ((performance.now() - lastMessageAt) / 1000).toFixed(0) + ' s ago' : '–';
}, 1000);

$('reset').addEventListener('click', () => view.resetView());

// Colouring: the labels' own colours, or how far each part is from the slices that saw it.
function setColoring() {
  const distance = $('color-distance').checked;
  const scale = Number($('scale-mm').value);
  view.setColorMode(distance ? 'distance' : 'label', scale);
  $('scale').hidden = !distance;
  $('scale-mid').textContent = scale / 2;
  $('scale-max').textContent = '≥ ' + scale;
}
$('scale-bar').style.background = rampCss();
for (const id of ['color-label', 'color-distance', 'scale-mm'])
  $(id).addEventListener('change', setColoring);
$('show-slices').addEventListener('change', () => view.setSlicesVisible($('show-slices').checked));
$('show-frame').addEventListener('change', () => view.setFrameVisible($('show-frame').checked));
// For bench/viewer_bench.mjs: the frame rate of orbiting the scene, each picture finished.
window.sonoshapeViewer.measureFps = (seconds) => new Promise((resolve) => {
  const start = performance.now();
  let frames = 0;
  const step = () => {
    view.orbitStep(0.02);
    view.finishDrawing();
    ++frames;
    const elapsed = (performance.now() - start) / 1000;
    if (elapsed < seconds) requestAnimationFrame(step);
    else resolve({ frames, seconds: elapsed, fps: frames / elapsed });
  };
  requestAnimationFrame(step);
});
// For tests and scripts: switch the colouring as the buttons do.
window.sonoshapeViewer.setColoring = (mode, scaleMm = 10) => {
  $(mode === 'distance' ? 'color-distance' : 'color-label').checked = true;
  $('scale-mm').value = String(scaleMm);
  setColoring();
};
$('screenshot').addEventListener('click',
  () => download(view.screenshot(), 'sonoshape-' + (scan ?? 'view').slice(0, 8) + '.png'));
// For tests: the header of a label's export and its size, as a download would write it.
window.sonoshapeViewer.exportMesh = (label, format) => {
  const bytes = view.exportMesh(label, format);
  if (!bytes) return null;
  const head = new Uint8Array(bytes, 0, Math.min(bytes.byteLength, 400));
  return { size: bytes.byteLength, head: [...head] };
};
window.addEventListener('keydown', (event) => {
  if (event.key === 'r' && event.target === document.body) view.resetView();
});
connect();
