#!/bin/bash
# libkpcn.so exports its public API and nothing else (libkpcn/CMakeLists.txt generates the
# version script from the public headers): every exported symbol is a function or object the
# installed headers declare, and, in a build with every module (FULL=1), every function they
# declare is exported, so an embedder neither links against internals that may change nor
# meets a declared function the library lacks.
# usage: test_exports.sh LIBKPCN_SO INCLUDE_DIR CC FULL WORKDIR
set -u
lib=$(realpath "$1") inc=$(realpath "$2") cc=$3 full=$4 work=$5
rm -rf "$work" && mkdir -p "$work" && cd "$work" || exit 1
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }

for h in "$inc"/kpcn/*.h; do echo "#include \"kpcn/$(basename "$h")\""; done >all.c
# -aux-info lists every prototype the headers declare, with its file (the compiler's own
# reading, not a regex over the text)
"$cc" -std=c11 -I"$inc" -fsyntax-only -aux-info aux.txt all.c || { echo "FAIL: headers"; exit 1; }
grep "$inc/kpcn/" aux.txt | grep -v 'static ' | grep -o 'kpcn_[A-Za-z0-9_]* *(' |
  tr -d ' (' | sort -u >declared.txt
# the one exported table (an extern object, which -aux-info does not list)
grep -h -o 'extern [^;(]*kpcn_[A-Za-z0-9_]*\[' "$inc"/kpcn/*.h | grep -o 'kpcn_[A-Za-z0-9_]*' >>declared.txt
sort -u -o declared.txt declared.txt
nm -D --defined-only "$lib" | awk '$2 != "A" {print $3}' | sed 's/@.*//' | sort -u >exported.txt
[ -s declared.txt ] || fail "no declarations found under $inc/kpcn"
[ -s exported.txt ] || fail "no exported symbols in $lib"

extra=$(comm -13 declared.txt exported.txt)
[ -z "$extra" ] && echo "ok: every exported symbol is declared in a public header ($(wc -l <exported.txt) symbols)" ||
  fail "exported but declared in no public header: $(echo $extra | head -c 600)"
if [ "$full" = 1 ]; then
  missing=$(comm -23 declared.txt exported.txt)
  [ -z "$missing" ] && echo "ok: every function the public headers declare is exported ($(wc -l <declared.txt))" ||
    fail "declared in a public header but not exported: $(echo $missing | head -c 600)"
fi
[ "$fails" -eq 0 ] && echo "exports: all checks passed"
exit "$fails"
