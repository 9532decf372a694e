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
expect_fail "'missing.exr': no such file" out.exr missing.exr -o out.exr
expect_fail "truncated.exr" out.exr truncated.exr "$REF" --relmse -o out.exr
expect_fail "garbage.exr" out.exr garbage.exr -o out.exr
expect_fail "'wide.exr' has an unsupported or absurd size 70000x1" out.exr wide.exr -o out.exr
expect_fail "cannot write 'nodir/out.exr'" "" "$REF" -o nodir/out.exr
expect_fail "PNG only supports 1-4 channels" out.png "$NOISY" -o out.png
# All or nothing: a later output or command that fails leaves none of the earlier ones.
expect_fail "PNG only supports 1-4 channels" out.exr "$NOISY" -o out.exr -o out.png
expect_fail "has no channel 'Q'" p.kps "$NOISY" "$REF" --patches:size=16:count=4:out=p.kps --ch Q
expect_fail "count= (random patches) and stride= (a regular grid) exclude each other" p.kps \
  "$NOISY" "$REF" --patches:size=16:count=4:stride=8:out=p.kps
expect_fail "has no channel 'Q'" pdir "$NOISY" "$REF" --patches:size=16:count=4:out=pdir --ch Q
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
[ -z "$(ls -a | grep -E '\.tmp|^out\.(exr|png)$|^map\.exr$')" ] && pass "no stray outputs" || fail "stray: $(ls -a)"
finish
