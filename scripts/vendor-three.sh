#!/usr/bin/env bash
# Fetch three.js from the npm registry (pinned version, integrity checked by npm) and copy the files the
# planner's view needs into service/static/vendor/three/ (committed: the page works offline, no CDN).
# Run again only to change the version: bash scripts/vendor-three.sh [version]
set -euo pipefail
VERSION="${1:-0.187.0}"
# sha512 of three-0.187.0.tgz as the registry publishes it (npm view three@0.187.0 dist.integrity)
INTEGRITY_0_187_0="sha512-Qiu7R+Cmh8CstZsY1uJOSWnVlfo7ZtNLV7mF8Jltk3LB3AtDu9cRZlcnRKkAk8Y4z6KKw35z7Y7Urd7jWY8etA=="
cd "$(dirname "$0")/.."
dest=service/static/vendor/three
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && npm pack --silent "three@$VERSION" >/dev/null)
tgz="$tmp/three-$VERSION.tgz"
got="sha512-$(openssl dgst -sha512 -binary "$tgz" | base64 -w0)"
if [ "$VERSION" = "0.187.0" ] && [ "$got" != "$INTEGRITY_0_187_0" ]; then
    echo "three-$VERSION.tgz: integrity $got differs from the pinned $INTEGRITY_0_187_0" >&2
    exit 1
fi
tar -xzf "$tgz" -C "$tmp"
mkdir -p "$dest"
cp "$tmp/package/build/three.core.js" "$tmp/package/build/three.module.js" \
   "$tmp/package/examples/jsm/controls/OrbitControls.js" "$tmp/package/LICENSE" "$dest/"
printf 'three %s from the npm registry (https://registry.npmjs.org/three)\nintegrity %s\nfiles: build/three.core.js, build/three.module.js, examples/jsm/controls/OrbitControls.js, LICENSE (MIT)\n' \
    "$VERSION" "$got" > "$dest/VERSION"
echo "three $VERSION -> $dest"
