// The 3D scene: one mesh per label, orbit controls, a view that frames what is shown. Draws only
// when something changed: the scan shares this workstation's processors.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { PLYExporter } from 'three/addons/exporters/PLYExporter.js';
import { STLExporter } from 'three/addons/exporters/STLExporter.js';

export class SceneView {
  /** @param {HTMLElement} container the element the canvas fills */
  constructor(container) {
    this.container = container;
    // preserveDrawingBuffer: the picture stays readable for screenshots.
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color('#1b1f24');
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.1, 1e5);
    this.camera.position.set(0, 0, 300);
    this.scene.add(new THREE.HemisphereLight('#ffffff', '#404040', 1.6));
    const headlight = new THREE.DirectionalLight('#ffffff', 1.4);
    this.camera.add(headlight);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => this.requestRender());
    this.controls.addEventListener('start', () => { this.userMoved = true; });
    this.meshes = new Map();  // label -> THREE.Mesh
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
      this.renderer.render(this.scene, this.camera);
      this.onRendered?.();
    });
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
    if (!this.userMoved) this.frameAll();
    this.requestRender();
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

  /** Removes every surface (a new scan began). */
  clear() {
    for (const mesh of this.meshes.values()) {
      this.scene.remove(mesh);
      mesh.geometry.dispose();
      mesh.material.dispose();
    }
    this.meshes.clear();
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
                                   { binary: true, littleEndian: true, excludeAttributes: ['normal'] });
  }

  /** The picture as drawn, a PNG data URL. */
  screenshot() {
    this.renderer.render(this.scene, this.camera);
    return this.renderer.domElement.toDataURL('image/png');
  }

  resetView() {
    this.userMoved = false;
    this.frameAll();
  }
}
