# Shared helpers for the kpcntool CLI tests: source it with "$@" = kpcntool testdata workdir.
set -u
KT=$1
TD=$2
WD=$3
rm -rf "$WD"
mkdir -p "$WD"
cd "$WD" || exit 1
NOISY=$TD/tungsten-cornell/noisy_16spp.exr
REF=$TD/tungsten-cornell/reference_2048spp.exr
fails=0
# Debian's interpreter starts fast; a pyenv shim on PATH can take half a second per call.
PY=python3
[ -x /usr/bin/python3 ] && PY=/usr/bin/python3
pass() { echo "ok: $*"; }
fail() {
  echo "FAIL: $*"
  fails=$((fails + 1))
}
# run_ok ARGS...: kpcntool must succeed; stdout in out.txt, stderr in err.txt.
run_ok() {
  if "$KT" "$@" >out.txt 2>err.txt; then
    pass "kpcntool $*"
  else
    fail "kpcntool $* exited $? : $(cat err.txt)"
  fi
}
# expect_fail PATTERN OUTFILE ARGS...: kpcntool must exit != 0, print PATTERN on stderr and
# leave neither OUTFILE (if non-empty) nor any temp file behind.
expect_fail() {
  local pat=$1 out=$2
  shift 2
  "$KT" "$@" >out.txt 2>err.txt
  local rc=$?
  if [ $rc -eq 0 ]; then
    fail "expected failure: kpcntool $*"
    return
  fi
  if ! grep -qF -- "$pat" err.txt; then
    fail "kpcntool $*: message lacks '$pat': $(cat err.txt)"
    return
  fi
  if [ -n "$out" ] && [ -e "$out" ]; then
    fail "kpcntool $*: output '$out' left behind"
    return
  fi
  if ls -a | grep -q '\.tmp'; then
    fail "kpcntool $*: temp file left: $(ls -a | grep '\.tmp')"
    return
  fi
  pass "fails (rc $rc) naming '$pat': kpcntool $*"
}
# json_get FILE KEY: prints the value of KEY in the JSON object in FILE.
json_get() { $PY -c 'import json,sys; print(repr(json.load(open(sys.argv[1]))[sys.argv[2]]))' "$1" "$2"; }
# near A B TOL: true if |A-B| <= TOL.
near() { $PY -c 'import sys; a,b,t=map(float,sys.argv[1:]); sys.exit(0 if abs(a-b)<=t else 1)' "$1" "$2" "$3"; }
near_rel() { $PY -c 'import sys; a,b,t=map(float,sys.argv[1:]); sys.exit(0 if abs(a-b)<=t*abs(b) else 1)' "$1" "$2" "$3"; }
finish() {
  if [ $fails -eq 0 ]; then
    echo "all passed"
    exit 0
  fi
  echo "$fails failed"
  exit 1
}
