// How the clay is drawn, for judging its form: the wireframe on or off (off by default past a few thousand nodes),
// smooth or flat shading, its look (the colour dims, a neutral studio clay or a matcap), back faces in a lighter
// colour of their own, a floor grid and the model's axes, and the control labels. Each view keeps its own settings.

import * as THREE from 'three';

export const LOOKS = ['colours', 'studio', 'matcap'];
export const SHADINGS = ['smooth', 'flat'];
export const WIREFRAME_DEFAULT_LIMIT = 3000; // display vertices past which a surface is drawn without its edges
const STUDIO = 0xb9b6b0; // a neutral clay grey
const BACK = new THREE.Color(0xf2d9b3); // back faces lean towards this light warm colour
const BACK_MIX = 0.55;

// Back faces (the clay's inside, seen through an opening) lighter and of their own colour, not near black.
function lighterBack(material) {
  material.onBeforeCompile = (shader) => {
    shader.uniforms.backColour = { value: BACK };
    shader.fragmentShader = `uniform vec3 backColour;\n${shader.fragmentShader}`
      .replace('#include <color_fragment>', `#include <color_fragment>
        if (!gl_FrontFacing) diffuseColor.rgb = mix(diffuseColor.rgb, backColour, ${BACK_MIX});`)
      .replace('#include <emissivemap_fragment>', `#include <emissivemap_fragment>
        if (!gl_FrontFacing) totalEmissiveRadiance += 0.35 * diffuseColor.rgb;`);
  };
  material.customProgramCacheKey = () => 'somview-lighter-back';
  return material;
}

let matcapTexture = null;
// A clay-like matcap made once: light from the upper left, a soft shadow towards the lower right, a darker rim.
function matcap() {
  if (matcapTexture) return matcapTexture;
  const c = document.createElement('canvas');
  c.width = c.height = 256;
  const g = c.getContext('2d');
  g.fillStyle = '#3c3a38';
  g.fillRect(0, 0, 256, 256);
  const body = g.createRadialGradient(100, 92, 8, 128, 128, 128);
  body.addColorStop(0, '#fbf8f2');
  body.addColorStop(0.35, '#d6d1c8');
  body.addColorStop(0.8, '#8e8a84');
  body.addColorStop(1, '#4a4744');
  g.fillStyle = body;
  g.beginPath();
  g.arc(128, 128, 128, 0, 2 * Math.PI);
  g.fill();
  matcapTexture = new THREE.CanvasTexture(c);
  return matcapTexture;
}

// The clay surface's material for a look and a shading; `lines`: the translucent quads of a lines display.
export function surfaceMaterial(look, shading, lines = false) {
  const common = { side: THREE.DoubleSide, flatShading: shading === 'flat', transparent: lines,
    opacity: lines ? 0.55 : 1.0, depthWrite: !lines };
  let m;
  if (look === 'studio') m = new THREE.MeshStandardMaterial({ ...common, color: STUDIO, roughness: 0.6, metalness: 0 });
  else if (look === 'matcap') m = new THREE.MeshMatcapMaterial({ ...common, matcap: matcap() });
  else m = new THREE.MeshLambertMaterial({ ...common, vertexColors: true });
  return lighterBack(m);
}

export class Display {
  // clay: the Clay it draws; onChange(): something drawn changed
  constructor(clay, onChange) {
    this.clay = clay;
    this.onChange = onChange;
    this.settings = { wireframe: null, shading: 'smooth', look: 'colours', grid: false, axes: false, labels: true };
    this.grid = null;
    this.axes = null;
  }

  // The wireframe as shown: the person's choice, else on for a surface of at most WIREFRAME_DEFAULT_LIMIT vertices.
  get wireframe() {
    const w = this.settings.wireframe;
    return w === null ? (this.clay.topology?.n_vertices ?? 0) <= WIREFRAME_DEFAULT_LIMIT : w;
  }

  // Change one setting (name in settings, value of its kind); returns false for an unknown one.
  set(name, value) {
    if (!(name in this.settings)) return false;
    if (name === 'look' && !LOOKS.includes(value)) return false;
    if (name === 'shading' && !SHADINGS.includes(value)) return false;
    this.settings[name] = name === 'look' || name === 'shading' ? value : Boolean(value);
    this.apply();
    return true;
  }

  // Draw the clay (a new topology, a changed setting) as the settings say.
  apply() {
    const clay = this.clay;
    const s = this.settings;
    if (clay.surface) {
      const lines = clay.topology?.display === 'lines';
      const old = clay.surface.material;
      clay.surface.material = surfaceMaterial(lines ? 'colours' : s.look, s.shading, lines);
      old.dispose();
    }
    clay.showSegments = clay.topology?.points || clay.topology?.display === 'lines' || this.wireframe;
    clay.setMoving(clay.moving);
    this.placeHelpers();
    this.onChange?.();
  }

  // The floor grid under the clay's start mesh (its lowest z) and the model's axes at its origin, in model units.
  placeHelpers() {
    const clay = this.clay;
    for (const h of [this.grid, this.axes]) {
      if (!h) continue;
      h.removeFromParent();
      h.geometry.dispose();
      h.material.dispose();
    }
    this.grid = this.axes = null;
    const t = clay.topology;
    if (!t) return;
    const span = 2 * clay.radius;
    if (this.settings.grid) {
      const step = 10 ** Math.floor(Math.log10(span / 4)); // a round spacing, 4 to 40 lines over the clay
      const size = Math.ceil((1.5 * span) / step) * step * 2;
      this.grid = new THREE.GridHelper(size, Math.round(size / step), 0x8890a8, 0xc4c8d4);
      this.grid.name = 'floor-grid';
      this.grid.rotation.x = Math.PI / 2; // its plane is the model's xy-plane
      this.grid.position.set(clay.centre.x, clay.centre.y, t.bounds.min[2]);
      clay.content.add(this.grid);
    }
    if (this.settings.axes) {
      this.axes = new THREE.AxesHelper(0.6 * span); // model x red, y green, z blue
      this.axes.name = 'model-axes';
      this.axes.material.depthTest = false;
      this.axes.renderOrder = 2;
      clay.content.add(this.axes);
    }
  }

  describe() {
    return { ...this.settings, wireframe: this.wireframe, wireframeChosen: this.settings.wireframe,
      grid: !!this.grid, axes: !!this.axes };
  }
}
