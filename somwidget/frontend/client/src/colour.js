// Imported first by main.js: vertex colours arrive as sRGB bytes and are drawn as they are, so no colour-space
// conversion anywhere (colour constants in the other modules are created after this runs).
import * as THREE from 'three';

THREE.ColorManagement.enabled = false;
