# Sourced (not run) by scripts/setup, scripts/sanitize and scripts/fuzz, with $repo set.
# ccache keys on the compile command; with the checkout's absolute path in it, a clone in another
# directory (CI's clean clone) would never hit the cache. Relative to the checkout it does; the
# cost is debug info whose compilation directory may name the clone that filled the cache.
# Set CCACHE_BASEDIR / CCACHE_NOHASHDIR yourself to override.
export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$repo}
export CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-true}
