// The soft-proof page's 3D view (three.js, inlined by inkopt.proof.page): a mesh with one texture per result,
// orbit and zoom, a swipe between two results (left and right of a split line) and the ΔE76 heat maps.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const D = JSON.parse(document.getElementById('inkopt-data').textContent);
const M = D.mesh;
const box = document.getElementById('view3d');
const stage = document.getElementById('stage3d');
const pick = document.getElementById('pick3d');
const other = document.getElementById('other3d');
const heat = document.getElementById('heat3d');
const swipe = document.getElementById('swipe3d');
const line = document.getElementById('line3d');
// a spectral run's light selector (valued by the light's index): textures under light i > 0 are M.by_light[i]
const light = document.getElementById('light');
const lightIndex = () => (light && Array.isArray(M.by_light) ? Number(light.value) : 0);

function floats(b64) {
  const s = atob(b64);
  const a = new Uint8Array(s.length);
  for (let i = 0; i < s.length; i++) a[i] = s.charCodeAt(i);
  return new Float32Array(a.buffer);
}

const renderer = new THREE.WebGLRenderer({ antialias: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
renderer.setClearColor(0xffffff, 1);
stage.appendChild(renderer.domElement);

const geometry = new THREE.BufferGeometry();
geometry.setAttribute('position', new THREE.BufferAttribute(floats(M.positions), 3));
geometry.setAttribute('normal', new THREE.BufferAttribute(floats(M.normals), 3));
geometry.setAttribute('uv', new THREE.BufferAttribute(floats(M.uv), 2));
geometry.computeBoundingSphere();
const radius = geometry.boundingSphere.radius;

// The pictures are sRGB of the predicted linear colour; the shader decodes them, darkens by a head-light for
// shape cues (1 - shade + shade cos) and encodes the result again, so an unshaded pixel shows the prediction.
const vertexShader = `
varying vec2 vUv; varying vec3 vN; varying vec3 vV;
void main() {
  vUv = uv;
  vec4 mv = modelViewMatrix * vec4(position, 1.0);
  vN = normalize(normalMatrix * normal); vV = -mv.xyz;
  gl_Position = projectionMatrix * mv;
}`;
const fragmentShader = `
uniform sampler2D map; uniform float shade;
varying vec2 vUv; varying vec3 vN; varying vec3 vV;
vec3 toLinear(vec3 c) { return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(0.04045, c)); }
vec3 toSrgb(vec3 c) { return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c)); }
void main() {
  float light = (1.0 - shade) + shade * max(dot(normalize(vN), normalize(vV)), 0.0);
  gl_FragColor = vec4(toSrgb(toLinear(texture2D(map, vUv).rgb) * light), 1.0);
}`;

const loader = new THREE.TextureLoader();
const materials = {};
function uriOf(key, isHeat) {
  const i = lightIndex();
  const set = i > 0 ? M.by_light[i] : null;
  const what = isHeat ? 'heat' : 'textures';
  return (set && set[what] && set[what][key]) || M[what][key];
}
function material(key, isHeat) {
  const id = lightIndex() + ':' + (isHeat ? 'heat:' : '') + key;
  if (!materials[id]) {
    const uri = uriOf(key, isHeat);
    const tex = loader.load(uri, () => draw());
    tex.colorSpace = THREE.NoColorSpace;
    tex.generateMipmaps = false;
    tex.minFilter = THREE.LinearFilter;
    tex.magFilter = THREE.LinearFilter;
    materials[id] = new THREE.ShaderMaterial({
      uniforms: { map: { value: tex }, shade: { value: D.shade } },
      vertexShader, fragmentShader,
    });
  }
  return materials[id];
}

const mesh = new THREE.Mesh(geometry, material(pick.value, false));
const scene = new THREE.Scene();
scene.add(mesh);
const camera = new THREE.PerspectiveCamera(30, 1, radius / 100, radius * 100);
camera.up.set(0, 0, 1);
const az = -Math.PI / 4, el = Math.PI / 9, dist = radius / Math.sin(Math.PI * 15 / 180) * 1.05;
camera.position.set(dist * Math.sin(az) * Math.cos(el), -dist * Math.cos(az) * Math.cos(el), dist * Math.sin(el));
const controls = new OrbitControls(camera, renderer.domElement);
controls.addEventListener('change', () => draw());

function resize() {
  const w = Math.max(stage.clientWidth, 1), h = Math.max(stage.clientHeight, 1);
  renderer.setSize(w, h, false);
  renderer.domElement.style.width = '100%';
  renderer.domElement.style.height = '100%';
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  draw();
}

function heatKey(key) { return heat.checked && uriOf(key, true) ? [key, true] : [key, false]; }

function draw() {
  document.body.dataset.light = String(lightIndex());
  const w = Math.max(stage.clientWidth, 1), h = Math.max(stage.clientHeight, 1);
  const [a, ah] = heatKey(pick.value);
  const right = other.value;
  renderer.setScissorTest(false);
  renderer.clear();
  if (!right) {
    mesh.material = material(a, ah);
    renderer.render(scene, camera);
    line.style.display = 'none';
    swipe.style.display = 'none';
    document.body.dataset.view = (ah ? 'heat:' : '') + a;
    return;
  }
  const [b, bh] = heatKey(right);
  const split = Math.round(w * swipe.value / 100);
  renderer.setScissorTest(true);
  renderer.setScissor(0, 0, split, h);
  mesh.material = material(a, ah);
  renderer.render(scene, camera);
  renderer.setScissor(split, 0, w - split, h);
  mesh.material = material(b, bh);
  renderer.render(scene, camera);
  renderer.setScissorTest(false);
  line.style.display = 'block';
  line.style.left = (100 * split / w) + '%';
  swipe.style.display = 'block';
  document.body.dataset.view = (ah ? 'heat:' : '') + a + '|' + (bh ? 'heat:' : '') + b;
}

function full() {
  document.body.classList.toggle('full3d', location.hash === '#3d');
  resize();
}

for (const el of [pick, other, heat, swipe, light]) if (el) el.addEventListener('input', () => draw());
new ResizeObserver(() => resize()).observe(stage);
window.addEventListener('hashchange', full);
full();
box.dataset.ready = '1';
