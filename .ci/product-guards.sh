#!/usr/bin/env bash
# The product stays apart from the lab and says what is true today:
# - the product crates (lodcloth, lodcloth-core) do not depend on the lab,
#   and on no plotting crate unless their own code draws with it;
# - the README stays within 200 lines, docs/results.md within 800;
# - no comment in the product's source carries a date (comments say why;
#   a measured figure lives in docs/results.md with its date).
# Fails naming what broke the rule.
set -euo pipefail
cd "$(dirname "$0")/.."
fail=0
plotting='^(plotters|plotly|charming|textplots|poloto|gnuplot)$'
for pkg in lodcloth lodcloth-core; do
  src=src
  [ "$pkg" = lodcloth-core ] && src=crates/lodcloth-core/src
  deps=$(cargo tree -p "$pkg" -e normal --prefix none --format '{p}' | awk '{print $1}' | sort -u)
  if grep -qx 'lodcloth-lab' <<< "$deps"; then
    echo "product-guards: $pkg depends on lodcloth-lab (cargo tree -p $pkg -e normal -i lodcloth-lab)"
    fail=1
  fi
  direct=$(cargo tree -p "$pkg" -e normal --depth 1 --prefix none --format '{p}' | awk 'NR > 1 {print $1}' | sort -u)
  for dep in $(grep -E "$plotting" <<< "$direct" || true); do
    if ! grep -rqE "\b${dep}::" "$src"; then
      echo "product-guards: $pkg depends on the plotting crate $dep but $src never uses it"
      fail=1
    fi
  done
  if [ "$pkg" = lodcloth-core ] && grep -qE "$plotting" <<< "$deps"; then
    echo "product-guards: lodcloth-core pulls a plotting crate: $(grep -E "$plotting" <<< "$deps" | tr '\n' ' ')"
    fail=1
  fi
done
lines=$(wc -l < README.md)
if [ "$lines" -gt 200 ]; then
  echo "product-guards: README.md is $lines lines, over 200: current figures go to docs/results.md, history to the lab's notebook"
  fail=1
fi
results=$(wc -l < docs/results.md)
if [ "$results" -gt 800 ]; then
  echo "product-guards: docs/results.md is $results lines, over 800: one current table per claim; superseded figures go to the lab's notebook"
  fail=1
fi
# A date (YYYY-MM-DD) on a comment line of the product's source.
dated=$(grep -rnE '^\s*//.*\b20[0-9]{2}-[0-9]{2}-[0-9]{2}\b' src crates/lodcloth-core/src || true)
if [ -n "$dated" ]; then
  echo "product-guards: comments carry dates (say why, not when; the figure and its date belong in docs/results.md):"
  echo "$dated"
  fail=1
fi
[ "$fail" = 0 ] && echo "product-guards: the product is apart from the lab, README $lines lines, results $results, no dated comment"
exit "$fail"
