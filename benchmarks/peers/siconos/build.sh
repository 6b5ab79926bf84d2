#!/usr/bin/env bash
# Build the Siconos peer of rfverify (issue 30): FCLIB + Siconos C numerics (GRFC3D_IPM) and the
# small driver rfverify calls (driver.c here), into a cache folder.  Idempotent: a second run with
# the same sources, patches and driver reuses the build, prints its prefix and takes seconds.
#
#   bash benchmarks/peers/siconos/build.sh [--siconos SRC] [--fclib SRC] [--prefix DIR] [--jobs N] [--force]
#
#   --siconos SRC  Siconos sources: a .tar.xz/.tar.gz archive or a checkout directory
#                  (env RFVERIFY_SICONOS_SRC; default ../shared/peers/siconos/siconos-*-numerics-src.tar.xz
#                  beside this repository)
#   --fclib SRC    FCLIB sources, same forms (env RFVERIFY_FCLIB_SRC; default ../shared/peers/siconos/fclib-*-src.tar.xz)
#   --prefix DIR   where to install (env RFVERIFY_SICONOS; default ${XDG_CACHE_HOME:-~/.cache}/rfverify/siconos-<commit>)
#   --jobs N       parallel compile jobs (default: number of cores)
#   --force        rebuild even when the prefix holds a build of the same inputs
#
# The last line printed on success is the prefix; point rfverify at it with RFVERIFY_SICONOS=<prefix>
# (the driver is <prefix>/bin/rfverify-siconos-driver).  The only change to the sources is the CSC
# reader fix of the two .patch files here (a patch already present in the sources is recognised).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../../.." && pwd)"
shared="$(cd "$repo/.." && pwd)/shared/peers/siconos"

siconos_src="${RFVERIFY_SICONOS_SRC:-}"
fclib_src="${RFVERIFY_FCLIB_SRC:-}"
prefix="${RFVERIFY_SICONOS:-}"
jobs="$(nproc 2>/dev/null || echo 2)"
force=0
while [ $# -gt 0 ]; do
  case "$1" in
    --siconos) siconos_src="$2"; shift 2 ;;
    --fclib) fclib_src="$2"; shift 2 ;;
    --prefix) prefix="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    --force) force=1; shift ;;
    -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
    *) echo "build.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

die() { echo "build.sh: $*" >&2; exit 1; }

pick_default() {  # the one archive matching a pattern in the shared peers folder
  local pattern="$1" found
  found=$(compgen -G "$shared/$pattern" | head -n 1 || true)
  [ -n "$found" ] || die "no $pattern in $shared; pass --siconos/--fclib (or RFVERIFY_SICONOS_SRC/RFVERIFY_FCLIB_SRC)"
  echo "$found"
}
[ -n "$siconos_src" ] || siconos_src="$(pick_default 'siconos-*-numerics-src.tar.*')"
[ -n "$fclib_src" ] || fclib_src="$(pick_default 'fclib-*-src.tar.*')"
[ -e "$siconos_src" ] || die "Siconos sources '$siconos_src' do not exist"
[ -e "$fclib_src" ] || die "FCLIB sources '$fclib_src' do not exist"

# An identifier of the sources: the commit in an archive's name or a checkout's HEAD, else a content hash.
source_id() {
  local src="$1" base
  base="$(basename "$src")"
  if [ -d "$src" ]; then
    if git -C "$src" rev-parse --short=8 HEAD >/dev/null 2>&1; then
      echo "$(git -C "$src" rev-parse --short=8 HEAD)$(git -C "$src" status --porcelain 2>/dev/null | grep -q . && echo -dirty || true)"
    else
      echo "dir-$(echo "$(cd "$src" && pwd)" | sha256sum | cut -c1-8)"
    fi
  elif [[ "$base" =~ ^[a-z]+-([0-9a-f]{7,40})- ]]; then
    echo "${BASH_REMATCH[1]}"
  else
    echo "$(sha256sum "$src" | cut -c1-8)"
  fi
}
sid="$(source_id "$siconos_src")"
fid="$(source_id "$fclib_src")"
[ -n "$prefix" ] || prefix="${XDG_CACHE_HOME:-$HOME/.cache}/rfverify/siconos-$sid"
mkdir -p "$prefix"
prefix="$(cd "$prefix" && pwd)"

recipe=2  # bump when the library part of this script changes (cmake options, install steps)
inputs_hash() {  # everything that changes the built library
  { echo "siconos=$sid fclib=$fid recipe=$recipe"; cat "$here/fclib-csc-reader-global.patch" \
      "$here/fclib-csc-reader-rolling.patch" "$here/siconos-options.cmake"; } | sha256sum | cut -c1-16
}
driver_hash() { cat "$here/driver.c" | sha256sum | cut -c1-16; }
lib_stamp="$prefix/.rfverify-numerics-stamp"
drv_stamp="$prefix/.rfverify-driver-stamp"
want_lib="$(inputs_hash)"
want_drv="$(driver_hash)-$want_lib"
driver="$prefix/bin/rfverify-siconos-driver"

numerics_lib() { compgen -G "$prefix/lib*/libsiconos_numerics.so" | head -n 1 || true; }

if [ "$force" = 0 ] && [ -f "$lib_stamp" ] && [ "$(cat "$lib_stamp")" = "$want_lib" ] && [ -n "$(numerics_lib)" ] \
   && [ -f "$drv_stamp" ] && [ "$(cat "$drv_stamp")" = "$want_drv" ] && [ -x "$driver" ]; then
  echo "build.sh: Siconos peer already built (siconos $sid, fclib $fid): reusing it"
  echo "$prefix"
  exit 0
fi

# --- Debian packages -------------------------------------------------------------------------
packages=(cmake g++ make pkg-config liblapacke-dev libopenblas-dev libsuitesparse-dev libhdf5-dev patch
          python3 python3-packaging python3-wheel)  # Siconos's configure requires these two modules
if command -v dpkg-query >/dev/null 2>&1; then
  missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ "${#missing[@]}" -gt 0 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
      echo "build.sh: installing missing Debian packages: ${missing[*]}"
      apt-get update -qq
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
    else
      die "missing Debian packages: ${missing[*]} (install them: sudo apt-get install ${missing[*]})"
    fi
  fi
else
  for c in cmake g++ make pkg-config patch; do
    command -v "$c" >/dev/null 2>&1 || die "'$c' not found; needed (Debian packages: ${packages[*]})"
  done
fi

# --- numerics + FCLIB -----------------------------------------------------------------------
if [ "$force" = 1 ] || [ ! -f "$lib_stamp" ] || [ "$(cat "$lib_stamp")" != "$want_lib" ] || [ -z "$(numerics_lib)" ]; then
  rm -f "$lib_stamp" "$drv_stamp"
  work="$prefix/.work"
  rm -rf "$work"
  mkdir -p "$work"
  unpack() {  # unpack an archive or copy a checkout into $work/$2
    local src="$1" dest="$work/$2"
    mkdir -p "$dest"
    if [ -d "$src" ]; then
      cp -a "$src/." "$dest/"
    else
      tar -xf "$src" -C "$dest"
      # an archive holds one top folder: use it as the source root
      local top
      top=$(find "$dest" -mindepth 1 -maxdepth 1)
      if [ "$(echo "$top" | wc -l)" = 1 ] && [ -d "$top" ]; then echo "$top"; return; fi
    fi
    echo "$dest"
  }
  sdir="$(unpack "$siconos_src" siconos)"
  fdir="$(unpack "$fclib_src" fclib)"
  [ -f "$sdir/numerics/src/RollingFrictionContact/global_rolling_friction_3d_ipm.c" ] \
    || die "'$siconos_src' does not look like Siconos sources (no numerics/src/RollingFrictionContact/global_rolling_friction_3d_ipm.c)"
  [ -f "$fdir/src/fclib.h" ] || die "'$fclib_src' does not look like FCLIB sources (no src/fclib.h)"

  # The two readers' fixed lines are textually identical, so `patch` may match one function's hunk
  # in the other: apply forward first, then check that no unfixed line is left.
  for p in "$here/fclib-csc-reader-global.patch" "$here/fclib-csc-reader-rolling.patch"; do
    if patch -d "$sdir" -p1 --dry-run -s -f < "$p" >/dev/null 2>&1; then
      patch -d "$sdir" -p1 -s -f < "$p"
      echo "build.sh: $(basename "$p"): applied"
    elif patch -d "$sdir" -p1 -R --dry-run -s -f < "$p" >/dev/null 2>&1; then
      echo "build.sh: $(basename "$p"): already in the sources"
    else
      die "$(basename "$p") applies neither forward nor reversed to $siconos_src: fix its reader by hand (see the patch)"
    fi
  done
  reader="$sdir/numerics/src/FrictionContact/fclib_interface.c"
  if grep -nE 'int_to_csi\(fclib_problem->[MH]->i, [MH]->i, \(unsigned\)[MH]->nz\);' "$reader" >&2; then
    die "the CSC reader fix is not complete in $reader (lines above)"
  fi

  echo "build.sh: building FCLIB ($fid) into $prefix"
  cmake -S "$fdir" -B "$work/build-fclib" -DCMAKE_BUILD_TYPE=Release -DWITH_TESTS=OFF -DWITH_CXX=OFF \
    -DCMAKE_INSTALL_PREFIX="$prefix" > "$work/fclib-configure.log" 2>&1 \
    || { tail -n 30 "$work/fclib-configure.log" >&2; die "FCLIB configure failed (log: $work/fclib-configure.log)"; }
  cmake --build "$work/build-fclib" -j "$jobs" > "$work/fclib-build.log" 2>&1 \
    || { tail -n 30 "$work/fclib-build.log" >&2; die "FCLIB build failed (log: $work/fclib-build.log)"; }
  cmake --install "$work/build-fclib" > /dev/null

  echo "build.sh: building Siconos numerics ($sid) into $prefix (about 2 minutes with 2 jobs)"
  cmake -S "$sdir" -B "$work/build-siconos" -DUSER_OPTIONS_FILE="$here/siconos-options.cmake" \
    -DWITH_CXX=OFF -DWITH_FORTRAN=OFF -DCMAKE_BUILD_TYPE=Release -DSICONOS_CUSTOM_INSTALL="$prefix" \
    -Dfclib_ROOT="$prefix" -DCMAKE_PREFIX_PATH="$prefix" -DPython_EXECUTABLE=/usr/bin/python3 > "$work/siconos-configure.log" 2>&1 \
    || { tail -n 40 "$work/siconos-configure.log" >&2; die "Siconos configure failed (log: $work/siconos-configure.log)"; }
  cmake --build "$work/build-siconos" -j "$jobs" > "$work/siconos-build.log" 2>&1 \
    || { grep -m 20 -B 2 -A 5 "error" "$work/siconos-build.log" >&2 || tail -n 40 "$work/siconos-build.log" >&2;
         die "Siconos build failed (log: $work/siconos-build.log)"; }
  cmake --install "$work/build-siconos" --prefix "$prefix" > /dev/null
  [ -n "$(numerics_lib)" ] || die "no libsiconos_numerics.so under $prefix after the install"
  # The installed headers are flattened, but some still include "RollingFrictionContact/...":
  # keep the source tree's headers for the driver.
  rm -rf "$prefix/include/siconos-numerics-src"
  mkdir -p "$prefix/include/siconos-numerics-src"
  (cd "$sdir/numerics/src" && find . -name '*.h' -exec cp --parents {} "$prefix/include/siconos-numerics-src/" \;)
  rm -rf "$work"
  echo "$want_lib" > "$lib_stamp"
fi

# --- the driver -------------------------------------------------------------------------------
lib="$(numerics_lib)"
libdir="$(dirname "$lib")"
hdr="$(find "$prefix/include/siconos" -name GlobalRollingFrictionContactProblem.h | head -n 1)"
[ -n "$hdr" ] || die "GlobalRollingFrictionContactProblem.h not installed under $prefix/include"
cfg="$(find "$prefix/include" -name SiconosConfig.h | head -n 1)"
[ -n "$cfg" ] || die "SiconosConfig.h not installed under $prefix/include"
cs_dir=/usr/include/suitesparse  # CSparse's cs.h, which Siconos's headers include
[ -f "$cs_dir/cs.h" ] || cs_dir="$(dirname "$(find /usr/include /usr/local/include -name cs.h 2>/dev/null | head -n 1)")"
# The compile definitions numerics was built with (CS_LONG selects CSparse's 64-bit-index structs):
# a driver compiled without them would read the library's matrices with the wrong layout.
targets="$(find "$prefix" -name siconosTargets.cmake | head -n 1)"
[ -n "$targets" ] || die "siconosTargets.cmake not installed under $prefix"
defs="$(sed -n '/set_target_properties(Siconos::numerics /,/^)/p' "$targets" \
        | sed -n 's/.*INTERFACE_COMPILE_DEFINITIONS "\([^"]*\)".*/\1/p' | tr ';' '\n' | sed '/^$/d; s/^/-D/' | tr '\n' ' ')"
case "$defs" in *CS_LONG*|*CS_INT*) ;; *) [ "$(getconf LONG_BIT)" = 32 ] || die "no CS_LONG among numerics' definitions ($targets)";; esac
mkdir -p "$prefix/bin"
echo "build.sh: compiling the driver"
gcc -O2 -std=c11 -Wall $defs -o "$driver.tmp" "$here/driver.c" -I"$prefix/include/siconos-numerics-src" -I"$(dirname "$hdr")" -I"$(dirname "$cfg")" -I"$cs_dir" -L"$libdir" -lsiconos_numerics -lm \
  -Wl,-rpath,"$libdir" || die "the driver did not compile"
mv "$driver.tmp" "$driver"
echo "$want_drv" > "$drv_stamp"
echo "build.sh: Siconos peer built (siconos $sid, fclib $fid); use RFVERIFY_SICONOS=$prefix"
echo "$prefix"
