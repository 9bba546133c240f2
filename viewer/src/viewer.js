// The 3D viewer of o3d-seqcc's report.html (bundled by esbuild into o3d_seqcc/report/viewer.min.js).
//
// The page holds, inline: <div id="o3d-viewer"> with a <canvas> and radio buttons named "o3d-mode", and
// <script type="application/json" id="o3d-viewer-data"> with
//   glb        base64 GLB of the textured model (one primitive, unlit, Y-up)
//   modes      [{key, label, texture, lazy}]: texture = a data: URI with the same UV layout, or null for the GLB's
//              own; lazy: decoded only when the mode is first chosen (the full-resolution atlas)
//   selection  base64 of one uint16 per face (GLB face order): 0 = seen by no view, v + 1 = view v
//   palette    [[r, g, b], ...] 0..255, indexed like selection
//   camera     {position, target, fov}: the first view (a photo's viewpoint), world units, Y up
// Nothing is fetched: the model, the textures and this code are all in the one file.
// Until the model is drawn the element has data-state="loading" (the page shows a loading notice over the canvas,
// also while a lazy texture decodes); when done it sets data-state="drawn" (or "no-webgl" / "error: ...") and
// data-coverage (share of canvas pixels the model covers, read back from the drawing buffer).

import {
  AmbientLight, BufferAttribute, Color, DirectionalLight, MeshLambertMaterial, PerspectiveCamera, Scene,
  SRGBColorSpace, Texture, Vector3, WebGLRenderer,
} from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const BACKGROUND = 0xf2f2f2;

function decodeBase64(text) {
  const bin = atob(text);
  const out = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
  return out;
}

function loadImage(src) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error('texture image did not decode'));
    img.src = src;
  });
}

function selectionMesh(mesh, data) {
  // one colour per face: the geometry without shared vertices, a colour per corner
  const geo = mesh.geometry.index ? mesh.geometry.toNonIndexed() : mesh.geometry.clone();
  geo.deleteAttribute('uv');
  geo.computeVertexNormals();
  const sel = new Uint16Array(decodeBase64(data.selection).buffer);
  const pal = data.palette;
  const n = geo.attributes.position.count;
  const col = new Float32Array(3 * n);
  for (let f = 0; f < n / 3; f++) {
    const c = pal[Math.min(sel[f] ?? 0, pal.length - 1)];
    for (let k = 0; k < 3; k++) {
      const i = 9 * f + 3 * k;
      col[i] = c[0] / 255; col[i + 1] = c[1] / 255; col[i + 2] = c[2] / 255;
    }
  }
  // the palette's colours are sRGB values: vertex colours are in the renderer's linear working space
  for (let i = 0; i < col.length; i++) {
    const c = col[i];
    col[i] = c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
  }
  geo.setAttribute('color', new BufferAttribute(col, 3));
  const m = mesh.clone();
  m.geometry = geo;
  m.material = new MeshLambertMaterial({ vertexColors: true, flatShading: true, side: mesh.material.side });
  return m;
}

function coverage(renderer, canvas) {
  const gl = renderer.getContext();
  const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
  const px = new Uint8Array(4 * w * h);
  gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
  const bg = new Color(BACKGROUND);
  const br = Math.round(bg.r * 255), bgc = Math.round(bg.g * 255), bb = Math.round(bg.b * 255);
  let n = 0;
  for (let i = 0; i < px.length; i += 4) {
    if (Math.abs(px[i] - br) + Math.abs(px[i + 1] - bgc) + Math.abs(px[i + 2] - bb) > 12) n++;
  }
  return n / (w * h);
}

async function start(root) {
  const data = JSON.parse(document.getElementById('o3d-viewer-data').textContent);
  const canvas = root.querySelector('canvas');
  let renderer;
  try {
    renderer = new WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  } catch (e) {
    root.dataset.state = 'no-webgl';
    root.querySelector('.viewer-note').textContent =
      'This browser offers no WebGL, so the 3D view is off; the renders below show the model.';
    return;
  }
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.outputColorSpace = SRGBColorSpace;
  const scene = new Scene();
  scene.background = new Color(BACKGROUND);
  scene.add(new AmbientLight(0xffffff, 1.6));
  const sun = new DirectionalLight(0xffffff, 1.6);
  scene.add(sun);

  const glb = decodeBase64(data.glb);
  const gltf = await new GLTFLoader().parseAsync(glb.buffer, '');
  let mesh = null;
  gltf.scene.traverse((o) => { if (o.isMesh && !mesh) mesh = o; });
  if (!mesh) throw new Error('the GLB holds no mesh');
  scene.add(gltf.scene);
  const own = mesh.material.map;

  const textures = {};
  async function texture(mode) {
    const t = new Texture(await loadImage(mode.texture));
    t.flipY = false; // glTF's UV origin (top-left), like the GLB's own texture
    t.colorSpace = SRGBColorSpace;
    if (own) { t.wrapS = own.wrapS; t.wrapT = own.wrapT; t.magFilter = own.magFilter; t.minFilter = own.minFilter; }
    t.anisotropy = renderer.capabilities.getMaxAnisotropy();
    t.needsUpdate = true;
    return t;
  }
  for (const mode of data.modes) {
    if (!mode.texture) textures[mode.key] = own;
    else if (!mode.lazy) textures[mode.key] = await texture(mode);
  }
  if (own) own.anisotropy = renderer.capabilities.getMaxAnisotropy();
  let selection = null;

  const cam = data.camera;
  const camera = new PerspectiveCamera(cam.fov, 1, cam.near, cam.far);
  camera.position.fromArray(cam.position);
  camera.up.set(0, 1, 0);
  const controls = new OrbitControls(camera, canvas);
  controls.target.fromArray(cam.target);
  controls.enableDamping = false;
  controls.update();

  function resize() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== Math.round(w * renderer.getPixelRatio()) || canvas.height !== Math.round(h * renderer.getPixelRatio())) {
      renderer.setSize(w, h, false);
    }
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
  function draw() {
    resize();
    sun.position.copy(camera.position).sub(controls.target).normalize().add(new Vector3(0, 0.5, 0));
    renderer.render(scene, camera);
  }
  async function setMode(key) {
    const mode = data.modes.find((m) => m.key === key);
    if (mode && mode.lazy && !textures[key]) {
      root.dataset.state = 'loading';
      const notice = root.querySelector('.viewer-loading');
      if (notice) notice.textContent = 'Loading the texture: ' + mode.label + '…';
      textures[key] = await texture(mode);
      root.dataset.state = 'drawn';
    }
    if (key === 'selection') {
      if (!selection) { selection = selectionMesh(mesh, data); mesh.parent.add(selection); }
      mesh.visible = false;
      selection.visible = true;
    } else {
      if (selection) selection.visible = false;
      mesh.visible = true;
      mesh.material.map = textures[key] || own;
      mesh.material.needsUpdate = true;
    }
    root.dataset.mode = key;
    draw();
  }
  controls.addEventListener('change', draw);
  window.addEventListener('resize', draw);
  for (const input of root.querySelectorAll('input[name="o3d-mode"]')) {
    input.addEventListener('change', () => {
      if (input.checked) setMode(input.value).catch((e) => { root.dataset.state = 'error: ' + e.message; });
    });
  }
  const wanted = new URLSearchParams(location.hash.slice(1)).get('viewer');
  const keys = data.modes.map((m) => m.key).concat(['selection']);
  const first = keys.includes(wanted) ? wanted : keys[0];
  const radio = root.querySelector(`input[name="o3d-mode"][value="${first}"]`);
  if (radio) radio.checked = true;
  await setMode(first);
  root.dataset.coverage = coverage(renderer, canvas).toFixed(4);
  root.dataset.state = 'drawn';
}

const root = document.getElementById('o3d-viewer');
if (root) {
  start(root).catch((e) => {
    root.dataset.state = 'error: ' + e.message;
    const note = root.querySelector('.viewer-note');
    if (note) note.textContent = 'The 3D view could not start (' + e.message + '); the renders below show the model.';
  });
}
