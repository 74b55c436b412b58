#!/usr/bin/env bash
# The wire contract (proto/): `buf lint` (proto/buf.yaml: STANDARD), then
# `buf breaking` against the contract as it was at the commit named in
# proto/BASELINE, the last landed version (FILE rules: no renumbered,
# retyped, renamed or removed field, message or enum value).
#
# buf comes from npm (@bufbuild/buf ships the binary in a platform package),
# pinned; the baseline is read from this clone's own git history (a shallow
# clone fetches it from its origin first).
#
# A deliberate, compatible change to the contract (a new field, message or
# enum value) passes as it is. To move the baseline forward once a change has
# landed: git rev-parse HEAD > proto/BASELINE (in a later commit).
set -euo pipefail
cd "$(dirname "$0")/.."
BUF_VERSION=1.75.0
buf() { npx --yes "@bufbuild/buf@$BUF_VERSION" "$@"; }

BASELINE="$(tr -d '[:space:]' < proto/BASELINE)"
if ! [[ "$BASELINE" =~ ^[0-9a-f]{40}$ ]]; then
  echo "buf.sh: proto/BASELINE must hold one full 40-digit commit hash, not '$BASELINE'" >&2
  exit 1
fi
has_baseline() { git cat-file -e "$BASELINE^{commit}" 2> /dev/null; }
if ! has_baseline && git remote get-url origin > /dev/null 2>&1; then
  # A shallow or partial clone: fetch the history (or at least the commit)
  # from where it was cloned.
  echo "buf.sh: $BASELINE is not in this clone; fetching it from origin" >&2
  if [ "$(git rev-parse --is-shallow-repository)" = true ]; then
    timeout 300 git fetch --quiet --no-tags --unshallow origin || true
  fi
  has_baseline || timeout 120 git fetch --quiet --no-tags origin "$BASELINE" || true
fi
if ! has_baseline; then
  shallow="$(git rev-parse --is-shallow-repository 2> /dev/null || echo unknown)"
  echo "buf.sh: this clone lacks $BASELINE (proto/BASELINE, the last landed contract; shallow clone: $shallow)." >&2
  echo "        buf breaking needs it: fetch the full history (git fetch --unshallow) or the commit itself." >&2
  exit 1
fi
if [ "$(git rev-parse --is-shallow-repository)" != true ] && ! git merge-base --is-ancestor "$BASELINE" HEAD; then
  echo "buf.sh: proto/BASELINE ($BASELINE) is not an ancestor of HEAD: it must name a landed commit of this branch" >&2
  exit 1
fi
# The repository's own .git (the common one, should this be a worktree).
GITDIR="$(git rev-parse --path-format=absolute --git-common-dir)"

buf --version > /dev/null # fetch first, so that a registry problem is not taken for a lint failure
buf lint proto
echo "buf lint: proto/ passes STANDARD"
buf breaking proto --against "$GITDIR#format=git,ref=$BASELINE,subdir=proto"
echo "buf breaking: proto/ is compatible with the contract at $BASELINE"
