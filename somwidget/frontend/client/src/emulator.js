// The XR page on an emulated Meta Quest 3 (npm's iwer): for the browser tests and for trying the page without a
// headset. The emulated runtime replaces the browser's own navigator.xr (forceInstall: Chromium has one) before the
// app starts. `window.iwerDevice` is the emulated device: move its controllers and hands, press their buttons.

import { XRDevice, metaQuest3 } from 'iwer';

// ?stereo=1 renders both eyes; ?modes=vr emulates a headset without immersive-ar (the page then falls back to VR).
const params = new URLSearchParams(window.location.search);
const config = params.get('modes') === 'vr'
  ? { ...metaQuest3, name: 'Meta Quest 3 (VR only)', supportedSessionModes: ['inline', 'immersive-vr'] }
  : metaQuest3;
const device = new XRDevice(config, { stereoEnabled: params.get('stereo') === '1' });
device.installRuntime({ forceInstall: true });
window.iwerDevice = device;

await import('./main.js');
