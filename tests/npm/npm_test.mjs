// What the node tests share: their command-line arguments and the npm packages scripts/setup
// installs from tests/npm/package-lock.json into ${XDG_CACHE_HOME:-~/.cache}/avp/npm-test/<sha256
// of the lockfile>/node_modules (or AVP_NPM_TEST_DIR=<dir holding node_modules>).

import { createHash } from "node:crypto";
import { existsSync, readFileSync } from "node:fs";
import { createRequire } from "node:module";
import { homedir } from "node:os";
import { join } from "node:path";

/** The value after `--name` on the command line; exits 2 naming `script` when it is missing. */
export function arg(script, name) {
  const i = process.argv.indexOf(name);
  if (i < 0 || i + 1 >= process.argv.length) {
    console.error(`${script}: missing ${name} <value>`);
    process.exit(2);
  }
  return process.argv[i + 1];
}

/** A require() for the pinned npm packages of `lockfile`; exits 1 naming `test` and the first of
 * `packages` that is not installed (run scripts/setup). */
export function npmTestRequire(test, lockfile, packages) {
  const lockHash = createHash("sha256").update(readFileSync(lockfile)).digest("hex");
  const cacheRoot = process.env.XDG_CACHE_HOME || join(homedir(), ".cache");
  const installDir =
    process.env.AVP_NPM_TEST_DIR || join(cacheRoot, "avp", "npm-test", lockHash);
  const modules = join(installDir, "node_modules");
  for (const pkg of packages) {
    if (!existsSync(join(modules, pkg, "package.json"))) {
      console.error(`${test}: ${pkg} is not installed in ${modules}; run scripts/setup ` +
                    `(it installs tests/npm/package-lock.json there with npm ci)`);
      process.exit(1);
    }
  }
  return createRequire(join(modules, `avp-${test}.js`));
}
