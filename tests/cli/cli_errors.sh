# Usage errors and bad files: exit != 0, a message naming the problem, no output file, no
# temp file. (Bad images/channels/values: cli_badinput.sh.)
. "$(dirname "$0")/lib.sh"
oiiotool --create 70000x1 3 -o wide.exr
head -c 3000 "$NOISY" >truncated.exr
echo "not an image" >garbage.exr
# Usage errors (exit 2), detected before anything is read or written.
expect_fail "unknown command '--bogus'" out.exr "$NOISY" -o out.exr --bogus
expect_fail "unknown modifier 'foo' for --ssim" out.exr "$NOISY" "$REF" --ssim:foo=1 -o out.exr
expect_fail "unknown modifier 'x' for --info (it takes none)" "" "$NOISY" --info:x=1
expect_fail "modifier 'display' of --l1 needs a value" "" "$NOISY" "$REF" --l1:display
expect_fail "command '-o' needs 1 argument" "" "$NOISY" -o
expect_fail "nothing to do" "" 
expect_fail "nothing to do" "" --json --threads 1
expect_fail "modifier 'range' of --l1 is given twice" "" "$NOISY" "$REF" --l1:range=2:range=1
# -o's format is checked when the line is parsed: before a command that would fail at run time.
expect_fail "-o outfile: 'outfile' has no file extension" outfile "$REF" --colorswap -o outfile
expect_fail "-o out.xyz: no image format writes '.xyz' files" out.exr "$REF" -o out.exr -o out.xyz
[ "$("$KT" --bogus 2>/dev/null; echo $?)" = 2 ] && pass "usage error exits 2" || fail "usage exit code"
[ "$("$KT" "$REF" -o out.xyz 2>/dev/null; echo $?)" = 2 ] && pass "bad -o format exits 2" ||
  fail "bad -o format exit code"
# Files.
expect_fail "cannot open 'missing.exr': No such file or directory" out.exr missing.exr -o out.exr
expect_fail "truncated.exr" out.exr truncated.exr "$REF" --relmse -o out.exr
expect_fail "garbage.exr" out.exr garbage.exr -o out.exr
expect_fail "'wide.exr' has an unsupported or absurd size 70000x1" out.exr wide.exr -o out.exr
expect_fail "-o 'nodir/out.exr': folder 'nodir': No such file or directory" "" "$REF" -o nodir/out.exr
expect_fail "the image has 16 channels and .png files hold at most 4" out.png "$NOISY" -o out.png
# All or nothing: a later output or command that fails leaves none of the earlier ones.
expect_fail "the image has 16 channels and .png files hold at most 4" out.exr "$NOISY" -o out.exr -o out.png
expect_fail "has no channel 'Q'" p.kps "$NOISY" "$REF" --patches:size=16:count=4:out=p.kps --ch Q
expect_fail "count= (random patches) and stride= (a regular grid) exclude each other" p.kps \
  "$NOISY" "$REF" --patches:size=16:count=4:stride=8:out=p.kps
expect_fail "has no channel 'Q'" pdir "$NOISY" "$REF" --patches:size=16:count=4:out=pdir --ch Q
# session 60: no bound on count (99999999 ran ten minutes and filled the disk); a store from
# one image failed only at write time; a store of nothing (every candidate culled) was written
expect_fail "count=99999999 is more than 1048576 patches per image" p.kps "$NOISY" "$REF" \
  --patches:size=16:count=99999999:out=p.kps
expect_fail "a patch store needs the noisy image and its reference on top of it" p.kps "$NOISY" \
  --patches:size=16:count=4:out=p.kps
expect_fail "no patch kept (" p.kps "$NOISY" "$REF" --patches:size=16:count=4:cull=0:out=p.kps
# the store records the selection's figures and settings (its metadata said 0 candidates)
"$KT" "$TD/dataset/sample_noisy.exr" "$TD/dataset/sample_ref.exr" --patches:size=16:count=4:seed=2:out=st.kps \
  --json >st.json 2>err.txt ||
  fail "--patches to st.kps: $(cat err.txt)"
/usr/bin/python3 - st.kps st.json <<'PY' && pass "--patches: the store records stats and settings" ||
import json, re, sys
meta = open(sys.argv[1], "rb").read().decode("latin-1")
j = json.load(open(sys.argv[2]))
m = re.search(r'"stats":\{"candidates":(\d+),"kept":(\d+),"culled":(\d+)\}', meta)
assert m and [int(v) for v in m.groups()] == [j["patches_candidates"], j["patches_kept"],
                                               j["patches_culled"]], (m and m.groups(), j)
assert int(m.group(2)) > 0 and '"seed":2' in meta and '"size":16' in meta
PY
  fail "--patches: store metadata: $(strings st.kps | grep -o '"stats"[^}]*}' | head -1)"
rm -f st.kps st.json
expect_fail "has no channel 'Q'" pdir "$NOISY" "$REF" --patches:size=16:count=4:out=pdir/ --ch Q
# A directory named with a trailing slash (as docs/dataset.md writes it) is made next to its
# temporary copy, whether it exists yet or not; the second run merges into it.
for run in new existing; do
  run_ok "$NOISY" "$REF" --patches:size=16:count=4:seed=1:out=pdir/
  [ "$(ls pdir | tr '\n' ' ')" = "noisy_0000.exr noisy_0001.exr noisy_0002.exr noisy_0003.exr ref_0000.exr ref_0001.exr ref_0002.exr ref_0003.exr " ] &&
    pass "--patches:out=pdir/ ($run directory)" || fail "--patches:out=pdir/ ($run): $(ls -a pdir)"
done
rm -rf pdir
echo "a file" >pfile
expect_fail "'pfile/' exists and is not a directory" "" "$REF" -o ok.exr "$NOISY" "$REF" \
  --patches:size=16:count=4:out=pfile/
[ ! -e ok.exr ] && [ "$(cat pfile)" = "a file" ] && pass "out=FILE/ leaves every output alone" ||
  fail "out=pfile/ wrote: $(ls -a)"
rm -f pfile
run_ok "$REF" -o twice.exr --ch R,G,B,A=1 -o twice.exr
[ "$(oiiotool --info twice.exr | grep -c '4 channel')" = 1 ] && pass "the later of two -o to one file wins" ||
  fail "two -o to one file: $(oiiotool --info twice.exr)"
rm -f twice.exr
# Files that are not regular files: a FIFO or a device is neither read (it would block or
# never end) nor replaced by the renamed temporary; a symbolic link is written through.
mkfifo fifo.exr
[ "$(timeout 20 "$KT" fifo.exr --info 2>&1 >/dev/null)" = \
  "kpcntool: error: fifo.exr: cannot open 'fifo.exr': is not a regular file (a FIFO, device or socket)" ] &&
  pass "a FIFO as input is refused at once" || fail "FIFO input: $(timeout 20 "$KT" fifo.exr --info 2>&1)"
expect_fail "cannot open '/dev/zero': is not a regular file" "" /dev/zero --info
expect_fail "-o 'fifo.exr' is not a regular file (a FIFO, device or socket): it would be replaced" "" \
  "$REF" -o fifo.exr
[ -p fifo.exr ] && pass "the FIFO is still a FIFO" || fail "fifo.exr replaced: $(ls -l fifo.exr)"
ln -s /dev/null null.exr
expect_fail "-o 'null.exr' is not a regular file" "" "$REF" -o null.exr
[ -c /dev/null ] && [ -L null.exr ] && pass "/dev/null and the link to it are kept" || fail "null.exr: $(ls -l null.exr /dev/null)"
mkdir adir.exr
expect_fail "cannot open 'adir.exr': is a directory" "" adir.exr --info
expect_fail "-o 'adir.exr' is a directory" "" "$REF" -o adir.exr
ln -s gone.exr dangling.exr
expect_fail "-o 'dangling.exr' is a symbolic link to a missing file" "" "$REF" -o dangling.exr
rm -f fifo.exr null.exr dangling.exr
rmdir adir.exr
cp "$REF" target.exr
ln -s target.exr link.exr
run_ok "$NOISY" --ch R,G,B -o link.exr
[ -L link.exr ] && [ "$(oiiotool --info target.exr | grep -c '3 channel')" = 1 ] &&
  pass "-o through a symbolic link replaces its target, keeps the link" || fail "link.exr: $(ls -l link.exr target.exr)"
# An input image may be edited in place (every input is read before any output is written);
# a model a step reads may not be an output.
run_ok target.exr --ch R -o ./link.exr
[ "$(oiiotool --info target.exr | grep -c '1 channel')" = 1 ] && pass "an image edited in place (through a link)" ||
  fail "in-place edit: $(oiiotool --info target.exr)"
cp "$REF" model.png
expect_fail "-o 'model.png' is the same file as model 'model.png'" "" "$NOISY" \
  --denoise:model=model.png -o model.png
cmp -s "$REF" model.png && pass "the model is unchanged" || fail "model.png changed"
cp "$TD/scenes/cornell-box/scene.json" scene.exr
expect_fail "-o 'scene.exr' is the same file as the scene of --render 'scene.exr'" "" \
  --render:res=8x8:spp=1 scene.exr -o scene.exr
cmp -s "$TD/scenes/cornell-box/scene.json" scene.exr && pass "the scene is unchanged" || fail "scene.exr changed"
rm -f scene.exr
rm -f link.exr target.exr model.png
# A file name at the 255-byte limit: its temporary gets a short name in the same folder.
long=$(printf 'n%.0s' $(seq 1 251)).exr
run_ok "$REF" --ch R -o "$long"
[ -f "$long" ] && pass "a 255-byte file name is written" || fail "no $long"
rm -f "$long"
[ -z "$(ls -a | grep -E '\.tmp|^out\.(exr|png)$|^map\.exr$')" ] && pass "no stray outputs" || fail "stray: $(ls -a)"
finish
