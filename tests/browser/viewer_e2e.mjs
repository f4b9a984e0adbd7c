// The browser view end to end: a short simulated scan, `sonoshape view` following it, and Debian's
// chromium (headless, software WebGL) showing the page. Checks that every label's colour is in
// the rendered picture, that the page's status numbers match the scan's scan.json, and that the
// page's PLY and STL downloads hold the scan's final surfaces (their triangle counts). Then that a
// finished scan reads as finished (issue 40): the page says "finished" when the scan's publisher
// goes after its end, and a page open during `scan --view` (no --view-hold) keeps the finished
// scan, its counts and surfaces when the scan exits, never "lost".
//
// node tests/browser/viewer_e2e.mjs SONOSHAPE_BINARY WORK_DIR [SCREENSHOT.png [--full]]
// --full scans the default simulation (256 x 256 px, 30 fps, 6 s): the README's picture.
// Exits 77 (ctest: skipped) with the reason when chromium or three.js is missing. Only node's
// own modules: chromium is driven over its DevTools protocol on a pipe (chromium.mjs).
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import zlib from 'node:zlib';
import { fileURLToPath } from 'node:url';
import { labelColor } from '../../viewer/src/palette.js';
import { findChromium, launchChromium, openPage } from './chromium.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const [sonoshape, workDir, screenshotPath, mode] = process.argv.slice(2);
const kWidth = 1200;
const kHeight = 800;
const kPanelWidth = 300;  // the side panel (style.css): colours are counted left of it
const kMinPixels = 150;   // of each label's colour in the scene
const children = [];

function skip(reason) {
  console.log('SKIPPED: ' + reason);
  process.exit(77);
}

function fail(reason) {
  console.error('FAILED: ' + reason);
  for (const child of children) child.kill('SIGKILL');
  process.exit(1);
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// Starts a program with its output collected; `waitFor(regex)` resolves with the first match.
function start(command, args) {
  const child = spawn(command, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  children.push(child);
  let output = '';
  child.stdout.on('data', (d) => { output += d; });
  child.stderr.on('data', (d) => { output += d; });
  child.output = () => output;
  child.waitFor = async (pattern, timeoutMs) => {
    const deadline = Date.now() + timeoutMs;
    while (Date.now() < deadline) {
      const match = output.match(pattern);
      if (match) return match;
      if (child.exitCode !== null) break;
      await sleep(50);
    }
    fail(command + ' printed no ' + pattern + ' in ' + timeoutMs + ' ms:\n' + output);
  };
  child.exited = new Promise((resolve) => child.on('exit', (code) => resolve(code)));
  return child;
}

// Decodes an 8-bit RGB or RGBA PNG (what Page.captureScreenshot gives) into RGBA pixels.
function decodePng(png) {
  let at = 8;
  let width = 0;
  let height = 0;
  let channels = 0;
  const idat = [];
  while (at < png.length) {
    const length = png.readUInt32BE(at);
    const type = png.toString('ascii', at + 4, at + 8);
    const data = png.subarray(at + 8, at + 8 + length);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      if (data[8] !== 8 || data[12] !== 0) fail('PNG is not 8-bit, non-interlaced');
      channels = { 2: 3, 6: 4 }[data[9]];
      if (!channels) fail('PNG colour type ' + data[9]);
    } else if (type === 'IDAT') {
      idat.push(data);
    }
    at += 12 + length;
  }
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const pixels = Buffer.alloc(width * height * 4);
  let previous = Buffer.alloc(stride);
  for (let y = 0; y < height; ++y) {
    const filter = raw[y * (stride + 1)];
    const line = Buffer.from(raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1)));
    for (let x = 0; x < stride; ++x) {
      const a = x >= channels ? line[x - channels] : 0;
      const b = previous[x];
      const c = x >= channels ? previous[x - channels] : 0;
      let predictor = 0;
      if (filter === 1) predictor = a;
      else if (filter === 2) predictor = b;
      else if (filter === 3) predictor = (a + b) >> 1;
      else if (filter === 4) {
        const p = a + b - c;
        const pa = Math.abs(p - a);
        const pb = Math.abs(p - b);
        const pc = Math.abs(p - c);
        predictor = pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      }
      line[x] = (line[x] + predictor) & 0xff;
    }
    for (let x = 0; x < width; ++x)
      for (let k = 0; k < 4; ++k)
        pixels[(y * width + x) * 4 + k] = k < channels ? line[x * channels + k] : 255;
    previous = line;
  }
  return { width, height, pixels };
}

function hueOf(r, g, b) {
  const max = Math.max(r, g, b);
  const min = Math.min(r, g, b);
  if (max === min) return { hue: 0, saturation: 0, value: max / 255 };
  const d = max - min;
  let hue = max === r ? ((g - b) / d) % 6 : max === g ? (b - r) / d + 2 : (r - g) / d + 4;
  hue = (hue * 60 + 360) % 360;
  return { hue, saturation: d / max, value: max / 255 };
}

// Pixels of the scene (left of the panel) whose hue is that of `color`, lit or shaded.
function countColour(image, color) {
  const target = hueOf(parseInt(color.slice(1, 3), 16), parseInt(color.slice(3, 5), 16),
                       parseInt(color.slice(5, 7), 16));
  let count = 0;
  const sceneWidth = image.width - kPanelWidth * (image.width / kWidth);
  for (let y = 0; y < image.height; ++y)
    for (let x = 0; x < sceneWidth; ++x) {
      const i = (y * image.width + x) * 4;
      const pixel = hueOf(image.pixels[i], image.pixels[i + 1], image.pixels[i + 2]);
      const distance = Math.min(Math.abs(pixel.hue - target.hue), 360 - Math.abs(pixel.hue - target.hue));
      if (pixel.saturation > 0.35 && pixel.value > 0.15 && distance < 10) ++count;
    }
  return count;
}

async function main() {
  if (!sonoshape || !workDir) fail('usage: viewer_e2e.mjs SONOSHAPE_BINARY WORK_DIR [SCREENSHOT.png]');
  const chromium = findChromium();
  if (!chromium) skip('chromium is not installed (scripts/install-deps installs it)');
  if (!fs.existsSync(path.join(here, '../../viewer/node_modules/three/build/three.module.js')))
    skip('three.js is not in viewer/node_modules (scripts/install-deps puts it there)');
  fs.rmSync(workDir, { recursive: true, force: true });
  fs.mkdirSync(workDir, { recursive: true });
  const started = Date.now();

  // A short simulated sweep played in real time, so that the view joins it while it runs. The
  // scan's own view (--view-hold, on a port of its own) only keeps the publisher up after the
  // scan, as at the bedside: messages a loaded machine drops come back with a fresh snapshot.
  const out = path.join(workDir, 'scan');
  const sweep = mode === '--full'
    ? ['--sweep-s', '6']
    : ['--width-px', '160', '--height-px', '160', '--frame-rate', '8', '--depth', '5', '--sweep-s', '4'];
  const scan = start(sonoshape, ['scan', '--source', 'sim:default', ...sweep, '--realtime',
    '--publish', 'tcp://127.0.0.1:*', '--snapshot', 'tcp://127.0.0.1:*', '--publish-frames', '5',
    '--view', '127.0.0.1:0', '--view-hold', '-o', out]);
  const [, pub, snapshot] = await scan.waitFor(/on (tcp:\/\/\S+) \(snapshot (tcp:\/\/\S+)\)/, 60000);
  const view = start(sonoshape, ['view', pub, '--snapshot', snapshot, '--http', '127.0.0.1:0']);
  const [, url] = await view.waitFor(/open (http:\/\/127\.0\.0\.1:\d+\/)/, 20000);

  const { browser, send } = launchChromium(chromium, { width: kWidth, height: kHeight,
                                                        userDataDir: path.join(workDir, 'chromium') });
  children.push(browser);
  const { sessionId, evaluate } = await openPage(send, url, kWidth, kHeight);

  await scan.waitFor(/scan: finished; \S+ shows it until Ctrl-C/, 60000);
  const summary = JSON.parse(fs.readFileSync(path.join(out, 'scan.json'), 'utf8'));

  // Wait until the page shows the finished scan: finished, every label drawn, a frame rendered.
  let state;
  for (let i = 0; i < 300; ++i) {
    state = await evaluate(pageState);
    if (state && state.state.startsWith('finished') && state.labelsDrawn >= 2 && state.rendered > 0 &&
        state.slicesDrawn === summary.slices && state.framesShown > 0) break;
    await sleep(100);
  }
  if (!state || !state.state.startsWith('finished') || state.slicesDrawn !== summary.slices)
    fail('the page never showed the finished scan with its ' + summary.slices + ' slices: ' + JSON.stringify(state));
  if (!state.frameHintHidden) fail('the page says no B-mode frames come from a scan that sends them');
  await sleep(500);  // the last requested frame
  if (String(summary.frames_received) !== state.frames)
    fail(`frames in: page ${state.frames}, scan.json ${summary.frames_received}`);
  if (String(summary.slices) !== state.slices)
    fail(`slices: page ${state.slices}, scan.json ${summary.slices}`);
  // Every slice of the scan drawn (those before the view joined came with the snapshot), a
  // B-mode frame on its plane (waited for above), and the latency.
  const drawn = state.slicesDrawn;
  if (!/^\d+$/.test(state.latency)) fail(`frame-to-mesh latency shown as ${state.latency}`);

  const { data } = await send('Page.captureScreenshot', { format: 'png' }, sessionId);
  const png = Buffer.from(data, 'base64');
  fs.writeFileSync(path.join(workDir, 'page.png'), png);
  if (screenshotPath) fs.writeFileSync(screenshotPath, png);
  const image = decodePng(png);
  // Every label the scan wrote a surface for (a short sweep may miss a small organ: an empty mesh).
  const faces = (file) => {
    const header = fs.readFileSync(path.join(out, file)).subarray(0, 1024).toString('latin1');
    return Number((header.match(/element face (\d+)/) ?? [0, 0])[1]);
  };
  const labels = fs.readdirSync(out).map((f) => f.match(/^label_(\d+)\.ply$/))
    .filter((m) => m && faces(m[0]) > 0).map((m) => Number(m[1]));
  if (labels.length < 2) fail('the scan wrote ' + labels.length + ' non-empty label meshes');
  for (const label of labels) {
    const count = countColour(image, labelColor(label));
    console.log(`label ${label} (${labelColor(label)}): ${count} pixels`);
    if (count < kMinPixels)
      fail(`label ${label}'s colour ${labelColor(label)} covers ${count} pixels (< ${kMinPixels}); see ${path.join(workDir, 'page.png')}`);
  }
  // What is still unscanned: the surfaces coloured by distance to the slices; the scanned parts
  // (0 mm) are the ramp's green, a hue no label of this scan has.
  await evaluate("window.sonoshapeViewer.setColoring('distance', 10)");
  let coverage = null;
  for (let i = 0; i < 50 && !coverage; ++i) {
    await sleep(100);
    coverage = await evaluate('window.sonoshapeViewer.coverage');
  }
  if (!coverage) fail('the page never coloured the surfaces by distance');
  await sleep(300);
  const distancePng = Buffer.from((await send('Page.captureScreenshot', { format: 'png' }, sessionId)).data, 'base64');
  fs.writeFileSync(path.join(workDir, 'distance.png'), distancePng);
  const coloured = decodePng(distancePng);
  const green = countColour(coloured, '#2ebf5c');
  console.log(`distance colouring: ${green} green (scanned) pixels; ${coverage.vertices} vertices in ${coverage.ms.toFixed(0)} ms`);
  if (green < kMinPixels) fail(`the distance colouring shows ${green} green pixels (< ${kMinPixels})`);
  await evaluate("window.sonoshapeViewer.setColoring('label')");

  // The page's downloads: each surface as PLY and STL, with the scan's own final triangle count.
  for (const label of labels) {
    const ply = await evaluate(`window.sonoshapeViewer.exportMesh(${label}, 'ply')`);
    const stl = await evaluate(`window.sonoshapeViewer.exportMesh(${label}, 'stl')`);
    if (!ply || !stl) fail(`label ${label}: the page exports no surface`);
    const header = Buffer.from(ply.head).toString('latin1');
    const plyFaces = Number((header.match(/element face (\d+)/) ?? [0, -1])[1]);
    const stlFaces = Buffer.from(stl.head).readUInt32LE(80);
    const expected = faces(`label_${label}.ply`);
    if (!header.startsWith('ply\nformat binary_little_endian 1.0') || plyFaces !== expected)
      fail(`label ${label}: PLY download has ${plyFaces} faces, the scan wrote ${expected}:\n${header}`);
    if (stlFaces !== expected || stl.size !== 84 + 50 * expected)
      fail(`label ${label}: STL download has ${stlFaces} triangles in ${stl.size} bytes, not ${expected}`);
  }
  console.log(`page: ${state.labels.join(', ')}; frames ${state.frames}, slices ${state.slices} ` +
              `(${drawn} planes drawn), ${state.framesShown} B-mode frames shown; ` +
              `${((Date.now() - started) / 1000).toFixed(1)} s`);

  await publisherGoesAfterTheEnd(scan, view, evaluate);
  await scanViewEndsWithItsScan(send, sessionId, evaluate, sweep);
  console.log(`finished scans read as finished; ${((Date.now() - started) / 1000).toFixed(1)} s`);
  for (const child of children) child.kill('SIGTERM');
  process.exit(0);
}

// What the page shows: its status table, connection line and counters.
const pageState = `({ ...window.sonoshapeViewer,
  state: document.getElementById('state')?.textContent ?? '',
  frames: document.getElementById('frames')?.textContent,
  slices: document.getElementById('slices')?.textContent,
  latency: document.getElementById('latency-ms')?.textContent,
  connection: document.getElementById('connection')?.textContent ?? '',
  connectionKind: document.getElementById('connection')?.className ?? '',
  frameHintHidden: document.getElementById('frame-hint')?.hidden,
  labels: [...document.querySelectorAll('#legend .name')].map((n) => n.textContent) })`;

// Polls the page until `done(state)`; fails with `what` and the last state otherwise.
async function waitForPage(evaluate, done, what, timeoutMs = 20000) {
  let state;
  for (const deadline = Date.now() + timeoutMs; Date.now() < deadline; await sleep(100)) {
    state = await evaluate(pageState);
    if (state && done(state)) return state;
  }
  fail(what + ': ' + JSON.stringify({ ...state, labels: undefined, drawLog: undefined }));
}

// The held scan stops (Ctrl-C): `sonoshape view` reports a normal end, not a missing publisher,
// and the page says the scan finished, with its surfaces still there.
async function publisherGoesAfterTheEnd(scan, view, evaluate) {
  scan.kill('SIGINT');
  if ((await scan.exited) !== 0) fail('the held scan did not exit 0 at Ctrl-C:\n' + scan.output());
  await view.waitFor(/view: scan \S+ finished \(\d+ slices.*publisher has closed/, 20000);
  if (/no mesh-stream publisher answered/.test(view.output()))
    fail('view reported the normal end of the scan as a missing publisher:\n' + view.output());
  const state = await waitForPage(evaluate, (s) => s.connection.includes('publisher has closed'),
                                  'the page did not say the scan finished when its publisher closed');
  if (state.connectionKind !== 'ok' || /lost/.test(state.connection) ||
      !state.state.startsWith('finished') || state.labelsDrawn < 2)
    fail('after the scan ended the page shows: ' + JSON.stringify(state.connection) + ', state ' +
         state.state + ', ' + state.labelsDrawn + ' labels');
}

// `scan --view` without --view-hold, as a user runs it: a page open during the scan keeps the
// finished scan (its counts against scan.json, its surfaces) when the scan exits and says why
// the server went; with --publish-frames 0 it says that no B-mode frames come.
async function scanViewEndsWithItsScan(send, sessionId, evaluate, sweep) {
  const out = path.join(workDir, 'scan-view');
  // Long enough for the page to load (three.js in software WebGL, on a loaded machine) and
  // connect while the scan runs: its end is what is checked.
  const longer = sweep.map((arg, i) => (sweep[i - 1] === '--sweep-s' ? '12' : arg));
  const scan = start(sonoshape, ['scan', '--source', 'sim:default', ...longer, '--realtime',
    '--publish', 'tcp://127.0.0.1:*', '--snapshot', 'tcp://127.0.0.1:*', '--publish-frames', '0',
    '--view', '127.0.0.1:0', '-o', out]);
  const [, url] = await scan.waitFor(/live view at (http:\/\/127\.0\.0\.1:\d+\/)/, 60000);
  await send('Page.navigate', { url }, sessionId);
  await waitForPage(evaluate, (s) => s.messages > 0, 'the page got nothing from scan --view');
  if (scan.exitCode !== null) fail('the page connected only after scan --view ended (too loaded?)');
  const code = await scan.exited;
  if (code !== 0) fail('scan --view exited ' + code + ':\n' + scan.output());
  if (!/closes with the scan: pages open now keep showing the finished scan/.test(scan.output()))
    fail('scan --view did not say what its page becomes:\n' + scan.output());
  const summary = JSON.parse(fs.readFileSync(path.join(out, 'scan.json'), 'utf8'));
  const state = await waitForPage(evaluate, (s) => s.connection.includes('stopped serving'),
                                  'the page did not say that the finished scan\'s server went');
  if (state.connectionKind !== 'ok' || /lost/.test(state.connection))
    fail('the page reads the end of scan --view as lost: ' + state.connection);
  if (!state.state.startsWith('finished') || state.slices !== String(summary.slices) ||
      state.frames !== String(summary.frames_received) || state.slicesDrawn !== summary.slices ||
      state.labelsDrawn < 2 || !state.finished)
    fail(`the page after scan --view: state ${state.state}, slices ${state.slices} ` +
         `(${state.slicesDrawn} drawn), frames ${state.frames}, ${state.labelsDrawn} labels; ` +
         `scan.json: ${summary.slices} slices, ${summary.frames_received} frames`);
  if (state.frameHintHidden) fail('the page does not say that the scan sends no B-mode frames');
  console.log(`scan --view ended: the page shows "${state.state}", ${state.slices} slices; ` +
              `"${state.connection}"`);
}

main().catch((e) => fail(e.stack || String(e)));
