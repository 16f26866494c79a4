// The report's 3D viewer (scan2morph.report.viewer bundles it with three.js into the page).
// The subject's .glb is base64 in #viewer3d's data-glb; the page's sliders, checkboxes and
// status line are written by Python. window.__viewer exposes the scene to the tests.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const root = document.getElementById('viewer3d');
const canvas = root.querySelector('canvas');
const status = root.querySelector('.viewer-status');

function fail(message) {
  root.dataset.state = 'error';
  status.textContent = 'The 3D viewer failed: ' + message;
  console.error('scan2morph viewer: ' + message);
}

function decode(base64) {
  const text = atob(base64);
  const bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
  return bytes.buffer;
}

function start() {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(canvas.width, canvas.height, false);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xe4e7eb);
  const camera = new THREE.PerspectiveCamera(30, canvas.width / canvas.height, 0.01, 10);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x556677, 1.2));
  const key = new THREE.DirectionalLight(0xffffff, 1.4);
  key.position.set(0.4, 0.5, 1.0);
  camera.add(key);
  scene.add(camera);
  const controls = new OrbitControls(camera, canvas);
  const render = () => renderer.render(scene, camera);
  controls.addEventListener('change', render);

  new GLTFLoader().parse(decode(root.dataset.glb), '', (gltf) => {
    let mesh = null;
    gltf.scene.traverse((o) => { if (o.isMesh && mesh === null) mesh = o; });
    if (mesh === null) { fail('the glTF holds no mesh'); return; }
    scene.add(gltf.scene);
    // camera on +Z looking down -Z at the face's middle, far enough to see all of it
    const box = new THREE.Box3().setFromObject(gltf.scene);
    const size = box.getSize(new THREE.Vector3());
    const centre = box.getCenter(new THREE.Vector3()).setZ(0);
    const tan = Math.tan(THREE.MathUtils.degToRad(camera.fov / 2));
    const distance = 1.2 * Math.max(size.y / 2 / tan, size.x / 2 / (tan * camera.aspect));
    camera.position.set(centre.x, centre.y, box.max.z + distance);
    camera.near = distance / 100;
    camera.far = 10 * (distance + size.length());
    camera.updateProjectionMatrix();
    controls.target.copy(centre);
    controls.update();

    const material = mesh.material;
    const map = material.map;
    const input = (name) => root.querySelector(`input[name="${name}"]`);
    input('texture').disabled = !map;
    input('texture').addEventListener('change', (e) => {
      material.map = e.target.checked ? map : null;
      material.needsUpdate = true;
      render();
    });
    input('wireframe').addEventListener('change', (e) => {
      material.wireframe = e.target.checked;
      render();
    });
    const sliders = Array.from(root.querySelectorAll('input[data-target]'));
    const show = (slider) => {
      mesh.morphTargetInfluences[Number(slider.dataset.target)] = Number(slider.value);
      slider.nextElementSibling.value = Number(slider.value).toFixed(2);
    };
    for (const slider of sliders) {
      slider.addEventListener('input', () => { show(slider); render(); });
    }
    root.querySelector('button[name="reset"]').addEventListener('click', () => {
      for (const slider of sliders) { slider.value = 0; show(slider); }
      render();
    });
    render();
    window.__viewer = { THREE, renderer, scene, camera, controls, mesh, render };
    root.dataset.state = 'ready';
    status.textContent = '';
  }, (err) => fail(String((err && err.message) || err)));
}

try {
  start();
} catch (err) {
  fail(String((err && err.message) || err));
}
