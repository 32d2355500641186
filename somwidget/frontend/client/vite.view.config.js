// Builds the clay view as one self-contained ES module, dist/somview.js (three.js inside, no imports left): the web
// app's page loads it from /xr/somview.js and Jupyter loads it as the notebook widget's module (anywidget).
// A plain (not library) build, so that it is minified; its exports are kept as the entry's signature.
import { resolve } from 'node:path';
import { defineConfig } from 'vite';

export default defineConfig({
  build: {
    outDir: 'dist',
    emptyOutDir: false,
    target: 'es2022',
    chunkSizeWarningLimit: 1500,
    modulePreload: false,
    rollupOptions: {
      input: resolve(import.meta.dirname, 'src/somview.js'),
      preserveEntrySignatures: 'strict',
      output: { format: 'es', entryFileNames: 'somview.js', inlineDynamicImports: true },
    },
  },
});
