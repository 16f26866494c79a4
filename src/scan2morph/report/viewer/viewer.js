// The report's 3D viewer (scan2morph.report.viewer bundles it with three.js into the page).
// #viewer3d carries the subject's .glb (base64, data-glb), the viewer's own data (data-layout:
// JSON, data-block: base64 of int16 displacement vectors, see viewer.viewer_data) and the
// controls written by the page's template. window.__viewer exposes the scene to the tests.
//
// What is drawn: the glTF's base (the neutral) + the glTF's morph targets at the semantic
// sliders' weights (three.js morphs them on the GPU) + the modal displacement sum_i q_i mode_i
// (+ an expression preset's remaining modes), added to the base positions here; or, when a take
// is picked, the take's aligned mesh (faces on its invalid vertices hidden, morphs off).
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const root = document.getElementById('viewer3d');
const canvas = root.querySelector('canvas');
const status = root.querySelector('.viewer-status');
const INVALID = -32768;

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

// One quantized (V, 3) vector of the block: Float32Array of metres, NaN where invalid.
function vector(block, entry, count) {
  const steps = new Int16Array(block, entry.offset, 3 * count);
  const out = new Float32Array(3 * count);
  for (let i = 0; i < out.length; i++) {
    out[i] = steps[i] === INVALID ? NaN : steps[i] * entry.scale;
  }
  return out;
}

function start() {
  const layout = JSON.parse(root.dataset.layout);
  const block = decode(root.dataset.block || '');
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
    const geometry = mesh.geometry;
    const position = geometry.attributes.position;
    const normal = geometry.attributes.normal;
    const count = position.count;
    if (count !== layout.vertices) {
      fail(`the glTF has ${count} vertices, the store ${layout.vertices}`);
      return;
    }
    scene.add(gltf.scene);
    mesh.frustumCulled = false; // the vertices move on the CPU too
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

    const basePosition = position.array.slice();
    const baseNormal = normal ? normal.array.slice() : null;
    const fullIndex = geometry.index;
    const modes = layout.modes.map((m) => vector(block, m, count));
    const presets = layout.presets.map((p) => ({ ...p, restVector: p.rest ? vector(block, p.rest, count) : null }));
    const takes = layout.takes.map((t) => ({ ...t, vector: vector(block, t, count) }));
    const q = new Float64Array(modes.length);
    const state = { preset: null, take: null };

    const input = (name) => root.querySelector(`[name="${name}"]`);
    const weightSliders = Array.from(root.querySelectorAll('input[data-target]'));
    const modeSliders = Array.from(root.querySelectorAll('input[data-mode]'));
    const takeSelect = input('take');
    const takeNote = root.querySelector('.take-note');
    const presetNote = root.querySelector('.preset-note');
    const material = mesh.material;
    const map = material.map;
    const fmt = (x) => (Math.abs(x) >= 0.01 || x === 0 ? x.toFixed(2) : x.toExponential(1));

    // the base positions (and normals) of the current state
    function update() {
      const pos = position.array;
      const take = state.take === null ? null : takes[state.take];
      const rest = state.preset === null ? null : presets[state.preset].restVector;
      const moved = take !== null || rest !== null || q.some((x) => x !== 0);
      pos.set(basePosition);
      if (take !== null) {
        const d = take.vector;
        for (let i = 0; i < pos.length; i++) if (!Number.isNaN(d[i])) pos[i] += d[i];
        geometry.setIndex(take.index);
      } else {
        for (let k = 0; k < modes.length; k++) {
          if (q[k] === 0) continue;
          const m = modes[k];
          for (let i = 0; i < pos.length; i++) pos[i] += q[k] * m[i];
        }
        if (rest !== null) for (let i = 0; i < pos.length; i++) pos[i] += rest[i];
        geometry.setIndex(fullIndex);
      }
      position.needsUpdate = true;
      if (normal) {
        if (moved) geometry.computeVertexNormals();
        else normal.array.set(baseNormal);
        normal.needsUpdate = true;
      }
      const w = take === null;
      // a slider sets its target's weight (value / per); a PCA component's slider, in sigmas,
      // sets its pos target for values above 0 and its neg target (data-negative) below
      const influences = mesh.morphTargetInfluences;
      weightSliders.forEach((s) => {
        s.disabled = !w;
        const value = w ? Number(s.value) / Number(s.dataset.per || 1) : 0;
        if (s.dataset.negative === undefined) {
          influences[Number(s.dataset.target)] = value;
        } else {
          influences[Number(s.dataset.target)] = Math.max(value, 0);
          influences[Number(s.dataset.negative)] = Math.max(-value, 0);
        }
      });
      modeSliders.forEach((s) => { s.disabled = !w; });
      render();
    }

    // the faces of a take whose three vertices are valid
    for (const take of takes) {
      const ok = (v) => !Number.isNaN(take.vector[3 * v]);
      const kept = [];
      const idx = fullIndex.array;
      for (let f = 0; f < idx.length; f += 3) {
        if (ok(idx[f]) && ok(idx[f + 1]) && ok(idx[f + 2])) kept.push(idx[f], idx[f + 1], idx[f + 2]);
      }
      take.index = new THREE.BufferAttribute(new Uint32Array(kept), 1);
    }

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
    const showWeight = (slider) => {
      slider.nextElementSibling.value = Number(slider.value).toFixed(2);
    };
    for (const slider of weightSliders) {
      slider.addEventListener('input', () => { showWeight(slider); update(); });
    }
    const showMode = (k) => {
      modeSliders[k].nextElementSibling.value = fmt(q[k]);
    };
    modeSliders.forEach((slider, k) => {
      slider.addEventListener('input', () => { q[k] = Number(slider.value); showMode(k); update(); });
    });
    const setPreset = (j) => {
      state.preset = j;
      const p = j === null ? null : presets[j];
      for (let k = 0; k < q.length; k++) {
        q[k] = p === null ? 0 : p.q[k];
        modeSliders[k].value = q[k];
        showMode(k);
      }
      if (presetNote) {
        presetNote.textContent = p === null ? '' : (
          `${p.take}${p.label ? ' (' + p.label + ')' : ''}: its modal coordinates q1..q${q.length}` +
          ' on the sliders' + (p.rest ? ` + modes ${q.length + 1}..${p.modes} at its coordinates` : ''));
      }
      update();
    };
    root.querySelectorAll('button[data-preset]').forEach((b) => {
      b.addEventListener('click', () => setPreset(Number(b.dataset.preset)));
    });
    const zero = input('modal-zero');
    if (zero) zero.addEventListener('click', () => setPreset(null));
    const showTake = (j) => {
      state.take = j;
      takeSelect.value = j === null ? '' : String(j);
      const t = j === null ? null : takes[j];
      takeNote.textContent = t === null ? 'The model: the sliders set its shape.' : (
        `${t.take} (${t.kind}${t.label && t.label !== t.kind ? ' ' + t.label : ''}): ` +
        'the fitted mesh aligned to the ' +
        `neutral, ${t.valid} of ${count} vertices valid (faces on the others hidden; ` +
        "textured with the neutral's image); " +
        (t.aligned ? 'alignment gate passed.' : 'alignment gate FAILED (left out of the models).'));
      update();
    };
    if (takeSelect) {
      takeSelect.addEventListener('change', () => {
        showTake(takeSelect.value === '' ? null : Number(takeSelect.value));
      });
      const step = (by) => {
        const n = takes.length + 1; // the model, then each take
        const at = state.take === null ? 0 : state.take + 1;
        const next = (at + by + n) % n;
        showTake(next === 0 ? null : next - 1);
      };
      input('prev-take').addEventListener('click', () => step(-1));
      input('next-take').addEventListener('click', () => step(1));
    }
    input('reset').addEventListener('click', () => {
      for (const slider of weightSliders) { slider.value = 0; showWeight(slider); }
      state.preset = null;
      if (takeSelect) showTake(null);
      setPreset(null);
    });

    // world positions of every vertex as drawn (three.js's CPU twin of its morphing shader)
    const positions = () => {
      const v = new THREE.Vector3();
      const out = new Array(3 * count);
      mesh.updateMatrixWorld(true);
      for (let i = 0; i < count; i++) {
        mesh.getVertexPosition(i, v).applyMatrix4(mesh.matrixWorld);
        out[3 * i] = v.x; out[3 * i + 1] = v.y; out[3 * i + 2] = v.z;
      }
      return out;
    };
    update();
    window.__viewer = { THREE, renderer, scene, camera, controls, mesh, render, positions, layout };
    root.dataset.state = 'ready';
    status.textContent = '';
  }, (err) => fail(String((err && err.message) || err)));
}

try {
  start();
} catch (err) {
  fail(String((err && err.message) || err));
}
