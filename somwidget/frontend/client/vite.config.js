// Builds the WebXR client into dist/ (served at /xr/ by server.py): index.html (the page for headsets and the
// desktop preview) and emulator.html (the same app on an emulated Quest 3, iwer, for tests). Relative asset paths
// (base './') so the pages work under /xr/ on any host.
import { resolve } from 'node:path';
import { defineConfig } from 'vite';

export default defineConfig({
  base: './',
  // `npm run dev` serves the pages on :5173; their websocket (/view/ws) goes to `somwidget serve` on :8080
  server: {
    proxy: { '/view/ws': { target: 'http://127.0.0.1:8080', ws: true } },
  },
  build: {
    outDir: 'dist',
    emptyOutDir: true,
    target: 'es2022',
    chunkSizeWarningLimit: 1500,
    rollupOptions: {
      input: {
        index: resolve(import.meta.dirname, 'index.html'),
        emulator: resolve(import.meta.dirname, 'emulator.html'),
      },
    },
  },
});
