// ESLint (flat config) for the browser client: `npm run lint` checks src/, the configs and tools/ with ESLint's
// recommended rules. src/ runs in the browser; the configs and tools/ run in Node.
import js from '@eslint/js';
import globals from 'globals';

export default [
  { ignores: ['dist/'] },
  js.configs.recommended,
  {
    languageOptions: { ecmaVersion: 2022, sourceType: 'module', globals: globals.browser },
  },
  {
    files: ['*.js', 'tools/**'],
    languageOptions: { globals: globals.node },
  },
];
