#!/usr/bin/env bash
# Side-by-side peer benchmark: the 10,242-vertex balloon of benches/body_balloon.rs stepped by
# Bullet's btSoftBody (bullet_balloon.cpp) and by our default implicit integrator, run
# alternately in the same session, so that the speed can be quoted as a ratio on a noisy,
# shared machine. Bullet is installed for this script only (Debian's libbullet-dev), never a
# dependency of the crate.
#   bash benches/peers/balloon_vs_bullet.sh [rounds (default 3)] [quick] [zerog] [interleaved]
# quick: 200 steps per run instead of 600.
# zerog: the zero-gravity scene instead (no ground; body_balloon.rs's zero-gravity run, 2
#        threads, which prints the mean step time only, so the median columns are left empty).
# interleaved: each round one process (balloon_interleaved.cpp, linked with Bullet and our
#        library) that steps the two balloons in turn, ten steps at a time, instead of two
#        whole runs one after the other (not with zerog). It also prints the mean over the
#        steps of each step's fastest round on each side (each round's step times in
#        target/peers/step_times_<round>.txt).
# Build flags of the C++ side: g++ -std=c++17 -O2, no -march=native (only the untimed driver is
# compiled here; Bullet is Debian's generic x86-64 build, as our crate is without
# target-cpu=native).
set -euo pipefail
cd "$(dirname "$0")/../.."

rounds=3
quick=""
zerog=""
interleaved=""
for arg in "$@"; do
  case "$arg" in
    quick) quick=quick ;;
    zerog) zerog=zerog ;;
    interleaved) interleaved=interleaved ;;
    *[!0-9]* | '') echo "usage: $0 [rounds] [quick] [zerog] [interleaved]" >&2; exit 2 ;;
    *) rounds=$arg ;;
  esac
done
[ "$rounds" -ge 1 ] || { echo "rounds must be at least 1" >&2; exit 2; }

if ! dpkg -s libbullet-dev >/dev/null 2>&1; then
  sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq libbullet-dev
fi
if pkg-config --exists bullet; then
  # -isystem: Bullet's headers are not ours to warn about.
  bullet_cflags=$(pkg-config --cflags-only-I bullet | sed 's/-I/-isystem /g')
  bullet_libs=$(pkg-config --libs bullet)
else
  bullet_cflags="-isystem /usr/include/bullet"
  bullet_libs="-lBulletSoftBody -lBulletDynamics -lBulletCollision -lLinearMath"
fi
mkdir -p target/peers
bullet=target/peers/bullet_balloon
# shellcheck disable=SC2086 # the flags are lists of words
g++ -std=c++17 -O2 -Wall -Wextra -o "$bullet" benches/peers/bullet_balloon.cpp $bullet_cflags $bullet_libs

# The median of the arguments ("-" for none).
median() { [ $# -gt 0 ] || { echo -; return; }; printf '%s\n' "$@" | sort -g | awk '{ v[NR] = $1 } END {
  print (NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2) }'; }

if [ -n "$interleaved" ]; then
  [ -z "$zerog" ] || { echo "interleaved runs the drop only, not zerog" >&2; exit 2; }
  cargo build --release --lib
  # The library where cargo put it (CARGO_TARGET_DIR or a cargo config may move it).
  libdir=$(cargo metadata --format-version 1 --no-deps | sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')/release
  [ -f "$libdir/libsoftshell.so" ] || { echo "no libsoftshell.so in $libdir" >&2; exit 1; }
  interleaved_bin=target/peers/balloon_interleaved
  # shellcheck disable=SC2086 # the flags are lists of words
  g++ -std=c++17 -O2 -Wall -Wextra -o "$interleaved_bin" benches/peers/balloon_interleaved.cpp -Iinclude \
    $bullet_cflags $bullet_libs -L"$libdir" -Wl,-rpath,"$libdir" -lsoftshell
  printf 'machine: %s cores, load average %s\n' "$(nproc)" "$(cut -d' ' -f1-3 /proc/loadavg)"
  printf '%5s | %-26s | %-26s | %s\n' round "Bullet (1 thread)" "ours, 2 threads (default)" "ours / Bullet"
  printf '%5s | %8s %8s %8s | %8s %8s %8s | %8s %8s\n' "" ms/step median V/V0 ms/step median V/V0 mean median
  ratios=(); median_ratios=(); phases=()
  field() { sed "s/.* $1=\([^ ]*\).*/\1/" <<<"$2"; } # the value of key $1 in the RESULT line $2
  step_times=()
  for round in $(seq 1 "$rounds"); do
    step_times+=("target/peers/step_times_$round.txt")
    out=$(STEP_TIMES="${step_times[-1]}" "$interleaved_bin" $quick || true)
    r=$(grep '^RESULT' <<<"$out" || true)
    phases+=("$(sed -n 's/^per 100 steps, softshell \/ Bullet (mean step times): //p' <<<"$out")")
    [ -n "$r" ] || { echo "round $round: balloon_interleaved printed no result:" >&2; echo "$out" >&2; exit 1; }
    for key in bullet_ms bullet_median bullet_settled ours_ms ours_median ours_settled ratio median_ratio nan; do
      grep -q " $key=" <<<"$r" || { echo "round $round: no $key in: $r" >&2; exit 1; }
    done
    [ "$(field nan "$r")" = 0 ] || echo "round $round: Bullet's balloon produced NaN" >&2
    ratios+=("$(field ratio "$r")"); median_ratios+=("$(field median_ratio "$r")")
    printf '%5s | %8.2f %8.2f %8.4f | %8.2f %8.2f %8.4f | %8.3f %8.3f\n' "$round" "$(field bullet_ms "$r")" \
      "$(field bullet_median "$r")" "$(field bullet_settled "$r")" "$(field ours_ms "$r")" \
      "$(field ours_median "$r")" "$(field ours_settled "$r")" "$(field ratio "$r")" "$(field median_ratio "$r")"
  done
  printf '\nmedian over %s interleaved rounds of ours (2 threads) / Bullet: %s (mean step times), %s (median step times)\n' \
    "$rounds" "$(median "${ratios[@]}")" "$(median "${median_ratios[@]}")"
  # Each step's fastest round on each side, then the mean over the steps: other processes on a
  # shared machine only ever add time to a step (more to ours, whose two threads wait for each
  # other, than to Bullet's one), so this keeps the least of their noise.
  awk '{ for (side = 2; side <= 3; side++) if (!(($1, side) in best) || $side < best[$1, side]) best[$1, side] = $side }
    END { for (key in best) { split(key, part, SUBSEP); total[part[2]] += best[key]; if (part[2] == 2) steps++ }
      printf "each step'"'"'s fastest of the %d rounds, mean over the steps: Bullet %.3f ms, ours %.3f ms, ours / Bullet %.4f\n",
        rounds, total[2] / steps * 1e3, total[3] / steps * 1e3, total[3] / total[2] }' rounds="$rounds" "${step_times[@]}"
  printf 'ours / Bullet per 100 steps (mean step times), round by round:\n'
  printf '  %s\n' "${phases[@]}"
  printf 'load average at the end: %s\n' "$(cut -d' ' -f1-3 /proc/loadavg)"
  exit 0
fi

# Our bench binary, as `cargo bench` runs it (the executable with --bench, then the arguments
# after --).
ours=$(cargo bench --bench body_balloon --no-run --message-format=json 2>/dev/null |
  grep -o '"executable":"[^"]*body_balloon[^"]*"' | tail -n 1 | cut -d'"' -f4)
[ -x "$ours" ] || { echo "could not build or find the body_balloon bench" >&2; exit 1; }

# BODY_ONLY (body_balloon.rs) runs the rows whose name contains the text (with a leading "="
# only the row of exactly that name): here the default 2-thread row and its 1-thread twin, no
# zero-gravity run and no cracking measurement. The rows print: name, ms/step, V/V0, min, max, CG it., "p10, median; CPU".
row() { # the numbers after the row name $1 (exact name) in the bench output on stdin
  awk -v name="$1" 'index($0, name) == 1 && substr($0, length(name) + 1, 1) == " " {
    print substr($0, length(name) + 1) }' | tr -d ',;'
}

printf 'machine: %s cores, load average %s\n' "$(nproc)" "$(cut -d' ' -f1-3 /proc/loadavg)"
if [ -n "$zerog" ]; then only="zero gravity"; else only="implicit Euler (default)"; fi
printf 'Bullet: %s %s; ours: %s (BODY_ONLY="%s")%s\n\n' "$bullet" "$zerog" "$ours" "$only" \
  "${quick:+, quick (200 steps)}"
printf '%5s | %-26s | %-26s | %-14s | %s\n' round "Bullet (1 thread)" "ours, 2 threads (default)" \
  "ours, 1 thread" "ours (2 threads) / Bullet"
printf '%5s | %8s %8s %8s | %8s %8s %8s | %14s | %8s %8s\n' "" ms/step median V/V0 ms/step median V/V0 ms/step \
  "mean" "median"
ratios=()
median_ratios=()
# Each side's times over the rounds, for the ratio of the best rounds (below).
b_means=(); b_medians=(); o_means=(); o_medians=()
for round in $(seq 1 "$rounds"); do
  # bullet_balloon exits with 1 when a node became NaN; its RESULT line still says so.
  b=$("$bullet" $quick $zerog | grep '^RESULT' || true)
  [ -n "$b" ] || { echo "round $round: bullet_balloon printed no result" >&2; exit 1; }
  b_ms=$(sed 's/.* ms=\([^ ]*\).*/\1/' <<<"$b")
  b_med=$(sed 's/.* median=\([^ ]*\).*/\1/' <<<"$b")
  b_vol=$(sed 's/.* settled=\([^ ]*\).*/\1/' <<<"$b")
  b_nan=$(sed 's/.* nan=\([^ ]*\).*/\1/' <<<"$b")
  out=$(BODY_ONLY="$only" "$ours" --bench $quick)
  if [ -n "$zerog" ]; then
    # "zero gravity, implicit Euler: settled V/V0 <v> (...), <ms> ms/step, ..."
    line=$(grep '^zero gravity, implicit Euler:' <<<"$out" || true)
    o_vol=$(sed -n 's/.*settled V\/V0 \([0-9.]*\).*/\1/p' <<<"$line")
    o_ms=$(sed -n 's/.*, \([0-9.]*\) ms\/step.*/\1/p' <<<"$line")
    o_med=""
    o1_ms=""
    case "$line" in *FAILED*) o_vol=UNSTABLE ;; esac
  else
    read -r o_ms o_vol _ _ _ _ o_med _ <<<"$(row "implicit Euler (default)" <<<"$out")"
    read -r o1_ms _ <<<"$(row "implicit Euler (default), 1 thread" <<<"$out")" || true
  fi
  if [ "${o_vol:-}" = UNSTABLE ] || [ -z "${o_ms:-}" ] || [ -z "${o_vol:-}" ]; then
    echo "round $round: our row failed or was not found:" >&2
    echo "$out" >&2
    exit 1
  fi
  ratio=$(awk -v o="$o_ms" -v b="$b_ms" 'BEGIN { printf "%.3f", o / b }')
  median_ratio=-
  if [ -n "$o_med" ]; then
    median_ratio=$(awk -v o="$o_med" -v b="$b_med" 'BEGIN { printf "%.3f", o / b }')
    median_ratios+=("$median_ratio")
  fi
  ratios+=("$ratio")
  b_means+=("$b_ms"); b_medians+=("$b_med"); o_means+=("$o_ms"); [ -z "$o_med" ] || o_medians+=("$o_med")
  printf '%5s | %8.2f %8.2f %8.4f | %8.2f %8s %8.4f | %14s | %8s %8s%s\n' "$round" "$b_ms" "$b_med" \
    "$b_vol" "$o_ms" "${o_med:--}" "$o_vol" "${o1_ms:--}" "$ratio" "$median_ratio" \
    "$([ "$b_nan" = 0 ] || echo '  (Bullet produced NaN)')"
done
printf '\nmedian over %s rounds of ours (2 threads) / Bullet: %s (mean step times), %s (median step times)\n' \
  "$rounds" "$(median "${ratios[@]}")" "$(median "${median_ratios[@]}")"
# The fastest round of each side (other processes on a shared machine only ever add time, and
# more to a run on two threads than to one on one): the ratio with the least noise in it.
least() { [ $# -gt 0 ] || { echo -; return; }; printf '%s\n' "$@" | sort -g | head -n 1; }
best_ratio() { # best ours, best Bullet
  [ "$1" != - ] && [ "$2" != - ] && awk -v o="$1" -v b="$2" 'BEGIN { printf "%.3f", o / b }' || echo -; }
printf 'fastest round of each, ours (2 threads) / Bullet: %s (mean step times), %s (median step times)\n' \
  "$(best_ratio "$(least "${o_means[@]}")" "$(least "${b_means[@]}")")" \
  "$(best_ratio "$(least "${o_medians[@]}")" "$(least "${b_medians[@]}")")"
printf 'load average at the end: %s\n' "$(cut -d' ' -f1-3 /proc/loadavg)"
