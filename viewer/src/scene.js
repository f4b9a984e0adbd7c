// The 3D scene: one mesh per label, the slice planes so far, the current B-mode frame on its
// plane with the probe, orbit controls, a view that frames what is shown. Draws only when
// something changed: the scan shares this workstation's processors.
import * as THREE from 'three';
import { distanceColor, distanceToSlices, slicePatch } from './coverage.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { PLYExporter } from 'three/addons/exporters/PLYExporter.js';
import { STLExporter } from 'three/addons/exporters/STLExporter.js';

export class SceneView {
  /** @param {HTMLElement} container the element the canvas fills */
  constructor(container) {
    this.container = container;
    // preserveDrawingBuffer: the picture stays readable for screenshots. No multisampling where
    // the GPU is emulated on the processors (a workstation without a graphics driver, headless
    // chromium): there it quadruples the cost of every picture (docs/benchmarks.md).
    this.gpu = gpuName();
    this.antialias = !/swiftshader|llvmpipe|softpipe|software/i.test(this.gpu);
    this.renderer = new THREE.WebGLRenderer({ antialias: this.antialias, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color('#1b1f24');
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.1, 1e5);
    // Oblique at first: the slices of a sweep are seen at an angle, not face on (a frame in
    // front of the surfaces would hide them).
    this.camera.position.set(190, 120, 190);
    this.scene.add(new THREE.HemisphereLight('#ffffff', '#404040', 1.6));
    const headlight = new THREE.DirectionalLight('#ffffff', 1.4);
    this.camera.add(headlight);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => this.requestRender());
    this.controls.addEventListener('start', () => { this.userMoved = true; });
    this.meshes = new Map();  // label -> THREE.Mesh
    this.slices = [];         // decoded slice messages, in the order they came
    this.sliceIndices = new Set();
    this.slicesChanged = false;
    this.patches = [];        // their planes and sectors (coverage.js)
    this.sliceGroup = new THREE.Group();
    this.scene.add(this.sliceGroup);
    this.frameView = null;    // { mesh, texture, probe } of the current B-mode frame
    this.colorMode = 'label'; // 'label' or 'distance' (what is still unscanned)
    this.distanceScaleMm = 10;
    this.onCoverage = null;   // called with {vertices, ms} after the distances are computed
    this.userMoved = false;
    this.renderQueued = false;
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const { clientWidth: width, clientHeight: height } = this.container;
    if (width === 0 || height === 0) return;
    this.renderer.setSize(width, height);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  requestRender() {
    if (this.renderQueued) return;
    this.renderQueued = true;
    requestAnimationFrame(() => {
      this.renderQueued = false;
      this.prepare();
      this.renderer.render(this.scene, this.camera);
      this.onRendered?.();
    });
  }

  // Slices and distances once per drawn picture: the slices and meshes of one update arrive
  // together.
  prepare() {
    if (this.slicesChanged) this.rebuildSlices();
    if (this.colorMode === 'distance') this.recolor();
  }

  /**
   * Shows the current surface of one label (replacing the previous one); an empty one hides it.
   * Until the user moves the camera, the view follows the growing surfaces.
   */
  setMesh(label, color, positions, indices, normals) {
    let mesh = this.meshes.get(label);
    if (!mesh) {
      const material = new THREE.MeshStandardMaterial({
        color, roughness: 0.6, metalness: 0.0, side: THREE.DoubleSide,
      });
      mesh = new THREE.Mesh(new THREE.BufferGeometry(), material);
      this.meshes.set(label, mesh);
      this.scene.add(mesh);
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    geometry.setIndex(new THREE.BufferAttribute(indices, 1));
    if (normals) geometry.setAttribute('normal', new THREE.BufferAttribute(normals, 3));
    else geometry.computeVertexNormals();
    geometry.computeBoundingBox();
    geometry.computeBoundingSphere();
    mesh.geometry.dispose();
    mesh.geometry = geometry;
    mesh.userData.labelColor = new THREE.Color(color);
    mesh.userData.distancesFor = -1;  // slices the distances were computed with: none yet
    if (!this.userMoved) this.frameAll();
    this.requestRender();
  }

  /**
   * Adds a slice (a decoded slice message) to the planes drawn: every slice's outline, the last
   * three emphasised, the newest filled. Surfaces coloured by distance take it into account. A
   * slice already shown (the same index: a fresh snapshot repeats them) is left as it is.
   */
  addSlice(slice) {
    if (this.sliceIndices.has(slice.index)) return;
    this.sliceIndices.add(slice.index);
    this.slices.push(slice);
    this.patches.push(slicePatch(slice));
    // Rebuilt once per drawn picture: a late page gets hundreds of slices at once.
    this.slicesChanged = true;
    this.requestRender();
  }

  rebuildSlices() {
    this.slicesChanged = false;
    for (const child of [...this.sliceGroup.children]) {
      this.sliceGroup.remove(child);
      child.geometry.dispose();
      child.material.dispose();
    }
    const kEmphasised = 3;
    const older = this.slices.slice(0, -kEmphasised);
    const recent = this.slices.slice(-kEmphasised);
    // Every older slice's outline in one draw call: hundreds of slices stay cheap.
    const segments = [];
    for (const slice of older) {
      const ring = outline(slice);
      for (let i = 0; i < ring.length; ++i)
        segments.push(...ring[i], ...ring[(i + 1) % ring.length]);
    }
    if (segments.length) {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.Float32BufferAttribute(segments, 3));
      this.sliceGroup.add(new THREE.LineSegments(geometry, new THREE.LineBasicMaterial(
        { color: '#8a9bb0', transparent: true, opacity: 0.35, depthWrite: false })));
    }
    recent.forEach((slice, k) => {
      const ring = outline(slice);
      if (ring.length < 3) return;
      const newest = k === recent.length - 1;
      const geometry = new THREE.BufferGeometry().setFromPoints(ring.map((p) => new THREE.Vector3(...p)));
      this.sliceGroup.add(new THREE.LineLoop(geometry, new THREE.LineBasicMaterial(
        { color: newest ? '#7df9ff' : '#3fb6c8', transparent: true, opacity: newest ? 1 : 0.75 })));
      if (!newest || this.frameView) return;  // the frame, when shown, fills the newest plane
      const fill = new THREE.BufferGeometry().setFromPoints(ring.map((p) => new THREE.Vector3(...p)));
      const flat = ring.map((p) => new THREE.Vector2(...planeCoords(slice.plane, p)));
      fill.setIndex(THREE.ShapeUtils.triangulateShape(flat, []).flat());
      this.sliceGroup.add(new THREE.Mesh(fill, new THREE.MeshBasicMaterial(
        { color: '#7df9ff', transparent: true, opacity: 0.15, side: THREE.DoubleSide, depthWrite: false })));
    });
    this.sliceGroup.visible = this.showSlices ?? true;
  }

  /** Shows or hides the slice planes. */
  setSlicesVisible(visible) {
    this.showSlices = visible;
    this.sliceGroup.visible = visible;
    this.requestRender();
  }

  /**
   * Shows a B-mode frame (a decoded frame message) textured on its plane, and the probe at its
   * top edge (row 0, the transducer side), replacing the previous frame.
   */
  setFrame(frame) {
    const first = !this.frameView;
    if (first) this.frameView = this.makeFrameView();
    const view = this.frameView;
    const { width, height, pixels, plane, sizeMm } = frame;
    if (!view.texture || view.texture.image.width !== width || view.texture.image.height !== height) {
      view.texture?.dispose();
      view.rgba = new Uint8Array(4 * width * height);
      view.texture = new THREE.DataTexture(view.rgba, width, height, THREE.RGBAFormat);
      view.texture.colorSpace = THREE.SRGBColorSpace;
      view.texture.magFilter = THREE.LinearFilter;
      view.mesh.material.map = view.texture;
      view.mesh.material.needsUpdate = true;
    }
    // Grey to opaque RGBA; black (outside the sector, no echo) see-through.
    const rgba = view.rgba;
    for (let i = 0, j = 0; i < pixels.length; ++i, j += 4) {
      const g = pixels[i];
      rgba[j] = rgba[j + 1] = rgba[j + 2] = g;
      rgba[j + 3] = g < 8 ? 0 : 255;
    }
    view.texture.needsUpdate = true;
    // Texture row 0 (v = 0) is the picture's row 0: the plane's origin side.
    const at = (a, b) => plane.origin.map((o, k) => o + a * plane.u[k] + b * plane.v[k]);
    const [w, h] = sizeMm;
    view.mesh.geometry.setAttribute('position', new THREE.Float32BufferAttribute(
      [...at(0, 0), ...at(w, 0), ...at(w, h), ...at(0, h)], 3));
    view.mesh.geometry.computeBoundingSphere();
    placeProbe(view.probe, plane, w);
    if (first) this.rebuildSlices();  // the frame replaces the newest slice's fill
    this.requestRender();
  }

  makeFrameView() {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('uv', new THREE.Float32BufferAttribute([0, 0, 1, 0, 1, 1, 0, 1], 2));
    geometry.setIndex([0, 1, 2, 0, 2, 3]);
    const mesh = new THREE.Mesh(geometry, new THREE.MeshBasicMaterial(
      { side: THREE.DoubleSide, transparent: true, opacity: 0.6, alphaTest: 0.02, depthWrite: false }));
    const probe = new THREE.Mesh(new THREE.BoxGeometry(1, 1, 1),
                                 new THREE.MeshStandardMaterial({ color: '#d8dde3', roughness: 0.4 }));
    mesh.visible = probe.visible = this.showFrame ?? true;
    this.scene.add(mesh, probe);
    return { mesh, probe, texture: null, rgba: null };
  }

  /** Shows or hides the B-mode frame and the probe. */
  setFrameVisible(visible) {
    this.showFrame = visible;
    if (this.frameView) this.frameView.mesh.visible = this.frameView.probe.visible = visible;
    this.requestRender();
  }

  /**
   * Colours the surfaces by their label ('label') or by how far each part is from the nearest
   * slice that saw it ('distance', green at 0 mm to red at scaleMm and beyond).
   */
  setColorMode(mode, scaleMm = this.distanceScaleMm) {
    const rescaled = scaleMm !== this.distanceScaleMm;
    this.colorMode = mode;
    this.distanceScaleMm = scaleMm;
    this.recolor(rescaled);
    this.requestRender();
  }

  recolor(force = false) {
    const started = performance.now();
    let vertices = 0;
    for (const mesh of this.meshes.values()) {
      if (this.colorMode === 'distance') {
        if (force) mesh.userData.distancesFor = -1;
        vertices += this.colorByDistance(mesh);
      } else {
        mesh.userData.distancesFor = -1;
        mesh.material.vertexColors = false;
        mesh.material.color.copy(mesh.userData.labelColor ?? mesh.material.color);
        mesh.material.needsUpdate = true;
      }
    }
    if (vertices) this.onCoverage?.({ vertices, ms: performance.now() - started });
  }

  // Colours one surface by distance when its surface or the slices changed; returns how many
  // vertices it coloured.
  colorByDistance(mesh) {
    const geometry = mesh.geometry;
    const positions = geometry.getAttribute('position');
    if (!positions || mesh.userData.distancesFor === this.patches.length) return 0;
    const scale = this.distanceScaleMm;
    const distances = distanceToSlices(positions.array, this.patches, scale);
    const colors = new Float32Array(3 * distances.length);
    const lut = colorTable(scale);
    for (let i = 0; i < distances.length; ++i) {
      const k = 3 * Math.min(255, Math.round((distances[i] / scale) * 255));
      colors[3 * i] = lut[k];
      colors[3 * i + 1] = lut[k + 1];
      colors[3 * i + 2] = lut[k + 2];
    }
    geometry.setAttribute('color', new THREE.BufferAttribute(colors, 3));
    mesh.userData.distancesFor = this.patches.length;
    mesh.material.vertexColors = true;
    mesh.material.color.set('#ffffff');
    mesh.material.needsUpdate = true;
    return distances.length;
  }

  setVisible(label, visible) {
    const mesh = this.meshes.get(label);
    if (mesh) mesh.visible = visible;
    this.requestRender();
  }

  /** @param {number} opacity 0 (invisible) to 1 (opaque) */
  setOpacity(label, opacity) {
    const mesh = this.meshes.get(label);
    if (!mesh) return;
    mesh.material.opacity = opacity;
    mesh.material.transparent = opacity < 1;
    // A see-through surface must not hide the ones behind it.
    mesh.material.depthWrite = opacity >= 1;
    mesh.material.needsUpdate = true;
    this.requestRender();
  }

  /** Removes every surface, slice and frame (a new scan began). */
  clear() {
    for (const mesh of this.meshes.values()) {
      this.scene.remove(mesh);
      mesh.geometry.dispose();
      mesh.material.dispose();
    }
    this.meshes.clear();
    this.slices = [];
    this.sliceIndices.clear();
    this.patches = [];
    this.rebuildSlices();
    if (this.frameView) {
      const { mesh, probe, texture } = this.frameView;
      this.scene.remove(mesh, probe);
      for (const m of [mesh, probe]) {
        m.geometry.dispose();
        m.material.dispose();
      }
      texture?.dispose();
      this.frameView = null;
    }
    this.userMoved = false;
    this.requestRender();
  }

  /** Points the camera at the box of the visible surfaces (the reset view). */
  frameAll() {
    const box = new THREE.Box3();
    for (const mesh of this.meshes.values())
      if (mesh.visible && mesh.geometry.boundingBox && !mesh.geometry.boundingBox.isEmpty())
        box.union(mesh.geometry.boundingBox);
    if (box.isEmpty()) return;
    const center = box.getCenter(new THREE.Vector3());
    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1);
    const distance = radius / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2));
    const direction = this.camera.position.clone().sub(this.controls.target).normalize();
    if (direction.lengthSq() === 0) direction.set(0, 0, 1);
    this.controls.target.copy(center);
    this.camera.position.copy(center).addScaledVector(direction, distance * 1.1);
    this.camera.near = distance / 100;
    this.camera.far = distance * 100;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.requestRender();
  }

  /**
   * The current surface of one label as a binary file, positions in mm in the stream's frame.
   * @param {'ply'|'stl'} format little-endian PLY (vertices and triangles) or binary STL
   * @returns {ArrayBuffer|null} null when the label has no surface
   */
  exportMesh(label, format) {
    const mesh = this.meshes.get(label);
    if (!mesh || !mesh.geometry.index || mesh.geometry.index.count === 0) return null;
    if (format === 'stl') return new STLExporter().parse(mesh, { binary: true }).buffer;
    return new PLYExporter().parse(mesh, null,
                                   { binary: true, littleEndian: true, excludeAttributes: ['normal', 'color'] });
  }

  /** Waits until the picture drawn so far is finished (a one-pixel read): for measurements. */
  finishDrawing() {
    const gl = this.renderer.getContext();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
  }

  /** Turns the camera about the view's target by `radians` and draws at once: for measurements. */
  orbitStep(radians) {
    const offset = this.camera.position.clone().sub(this.controls.target);
    offset.applyAxisAngle(this.camera.up, radians);
    this.camera.position.copy(this.controls.target).add(offset);
    this.camera.lookAt(this.controls.target);
    this.prepare();
    this.renderer.render(this.scene, this.camera);
  }

  /** The picture as drawn, a PNG data URL. */
  screenshot() {
    this.prepare();
    this.renderer.render(this.scene, this.camera);
    return this.renderer.domElement.toDataURL('image/png');
  }

  resetView() {
    this.userMoved = false;
    this.frameAll();
  }
}

// The name of the GPU (or of its software emulation) that WebGL draws with; '' when unknown.
function gpuName() {
  const gl = document.createElement('canvas').getContext('webgl2');
  if (!gl) return '';
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER) ?? '');
  gl.getExtension('WEBGL_lose_context')?.loseContext();
  return name;
}

// The outline of what a slice saw, as world points: its sector (fov), or, for a slice that saw
// its whole plane, the box of its regions.
function outline(slice) {
  let ring = slice.fov;
  if (!ring) {
    const points = slice.regions.flatMap((r) => r.polygon);
    if (!points.length) return [];
    const as = points.map((p) => p[0]);
    const bs = points.map((p) => p[1]);
    const [a0, a1, b0, b1] = [Math.min(...as), Math.max(...as), Math.min(...bs), Math.max(...bs)];
    ring = [[a0, b0], [a1, b0], [a1, b1], [a0, b1]];
  }
  const { origin, u, v } = slice.plane;
  return ring.map(([a, b]) => origin.map((o, k) => o + a * u[k] + b * v[k]));
}

// The in-plane coordinates of a world point of the plane.
function planeCoords(plane, point) {
  const r = point.map((x, k) => x - plane.origin[k]);
  const dot = (d) => r[0] * d[0] + r[1] * d[1] + r[2] * d[2];
  return [dot(plane.u), dot(plane.v)];
}

// The probe: a block on the picture's top edge (row 0, where the transducer sits), centred, as
// wide as a probe's face, standing away from the picture (-v) and as thick as a hand-held probe.
function placeProbe(probe, plane, widthMm) {
  const face = Math.min(Math.max(0.25 * widthMm, 10), 40);
  const [u, v] = [new THREE.Vector3(...plane.u), new THREE.Vector3(...plane.v)];
  const n = new THREE.Vector3().crossVectors(u, v);
  const centre = new THREE.Vector3(...plane.origin).addScaledVector(u, widthMm / 2)
    .addScaledVector(v, -0.4 * face);
  probe.matrixAutoUpdate = false;
  probe.matrix.makeBasis(u.multiplyScalar(face), v.multiplyScalar(0.8 * face), n.multiplyScalar(0.35 * face))
    .setPosition(centre);
}

// 256 colours of the distance ramp (0 .. scaleMm), linear RGB as vertex colours take them.
const colorTables = new Map();
function colorTable(scaleMm) {
  if (!colorTables.has(scaleMm)) {
    const table = new Float32Array(3 * 256);
    const color = new THREE.Color();
    for (let i = 0; i < 256; ++i) {
      color.setRGB(...distanceColor((i / 255) * scaleMm, scaleMm), THREE.SRGBColorSpace);
      table.set([color.r, color.g, color.b], 3 * i);
    }
    colorTables.set(scaleMm, table);
  }
  return colorTables.get(scaleMm);
}
