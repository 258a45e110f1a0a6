"""Helpers shared by the benchmark scripts (not part of the package)."""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # crash_factory: the feed-through / slow test FMU

MASTER_C = r"""
/* Pure C co-simulation master: the floor for the per-simulation time. */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

typedef void *C;
typedef struct {
    void (*logger)(void *, const char *, int, const char *, const char *, ...);
    void *(*alloc)(size_t, size_t);
    void (*free)(void *);
    void *stepFinished;
    void *env;
} Callbacks;

typedef C (*Inst)(const char *, int, const char *, const char *, const Callbacks *, int, int);
typedef int (*Setup)(C, int, double, double, int, double);
typedef int (*Comp)(C);
typedef int (*SetR)(C, const unsigned *, size_t, const double *);
typedef int (*GetR)(C, const unsigned *, size_t, double *);
typedef int (*Step)(C, double, double, int);

static void logger(void *e, const char *i, int s, const char *c, const char *m, ...) {
    (void)e; (void)i; (void)s; (void)c; (void)m; }

#define LOAD(T, name) T name = (T)dlsym(lib, #name); \
    if (!name) { fprintf(stderr, "missing %s\n", #name); return 2; }
#define CHECK(x, what, k) do { int s_ = (x); if (s_ > 1) { \
    fprintf(stderr, "%s failed (%d) at step %ld\n", what, s_, (long)(k)); return 3; } } while (0)

static double now(void) {
    struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts); return ts.tv_sec + 1e-9 * ts.tv_nsec; }

int main(int argc, char **argv) {
    /* lib guid resources data.bin n_in n_out vr_in... vr_out... repeats */
    if (argc < 7) return 1;
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    LOAD(Inst, fmi2Instantiate)
    LOAD(Setup, fmi2SetupExperiment)
    LOAD(Comp, fmi2EnterInitializationMode)
    LOAD(Comp, fmi2ExitInitializationMode)
    LOAD(Comp, fmi2Terminate)
    LOAD(Comp, fmi2Reset)
    LOAD(SetR, fmi2SetReal)
    LOAD(GetR, fmi2GetReal)
    LOAD(Step, fmi2DoStep)
    int n_in = atoi(argv[5]), n_out = atoi(argv[6]);
    unsigned vr_in[16], vr_out[16];
    for (int i = 0; i < n_in; i++) vr_in[i] = (unsigned)atoi(argv[7 + i]);
    for (int i = 0; i < n_out; i++) vr_out[i] = (unsigned)atoi(argv[7 + n_in + i]);
    int repeats = atoi(argv[7 + n_in + n_out]);
    FILE *f = fopen(argv[4], "rb"); long n;
    if (fread(&n, sizeof n, 1, f) != 1) return 4;
    double *t = malloc(n * sizeof *t), *u = malloc(n * (n_in ? n_in : 1) * sizeof *u);
    if (fread(t, sizeof *t, n, f) != (size_t)n) return 4;
    if (n_in && fread(u, sizeof *u, n * n_in, f) != (size_t)(n * n_in)) return 4;
    fclose(f);
    double *out = malloc(n * n_out * sizeof *out);
    Callbacks cb = {logger, calloc, free, NULL, NULL};
    C c = fmi2Instantiate("master", 1, argv[2], argv[3], &cb, 0, 0);
    if (!c) { fprintf(stderr, "instantiate failed\n"); return 5; }
    double best = 1e300, total = 0;
    for (int r = 0; r < repeats; r++) {
        double t0 = now();
        if (r) CHECK(fmi2Reset(c), "fmi2Reset", 0);
        CHECK(fmi2SetupExperiment(c, 0, 0.0, t[0], 1, t[n - 1]), "fmi2SetupExperiment", 0);
        CHECK(fmi2EnterInitializationMode(c), "fmi2EnterInitializationMode", 0);
        if (n_in) CHECK(fmi2SetReal(c, vr_in, n_in, u), "fmi2SetReal", 0);
        CHECK(fmi2ExitInitializationMode(c), "fmi2ExitInitializationMode", 0);
        CHECK(fmi2GetReal(c, vr_out, n_out, out), "fmi2GetReal", 0);
        /* the session's order: step t[k] -> t[k+1], set the inputs of t[k+1], get */
        for (long k = 0; k < n - 1; k++) {
            CHECK(fmi2DoStep(c, t[k], t[k + 1] - t[k], 1), "fmi2DoStep", k);
            if (n_in) CHECK(fmi2SetReal(c, vr_in, n_in, u + (k + 1) * n_in), "fmi2SetReal", k + 1);
            CHECK(fmi2GetReal(c, vr_out, n_out, out + (k + 1) * n_out), "fmi2GetReal", k + 1);
        }
        CHECK(fmi2Terminate(c), "fmi2Terminate", n - 1);
        double dt = now() - t0; total += dt; if (dt < best) best = dt;
    }
    printf("%.9g %.9g %.17g\n", best, total / repeats, out[(n - 1) * n_out]);
    return 0;
}
"""


def build_master(work: Path) -> Path:
    """Compile the pure C master with gcc -O2; return the executable."""
    src = work / "master.c"
    src.write_text(MASTER_C)
    exe = work / "master"
    subprocess.run(["gcc", "-O2", "-o", str(exe), str(src), "-ldl"], check=True)
    return exe


def run_master(exe: Path, fmu: Path, work: Path, t, u, inputs, outputs, repeats: int):
    """Run the C master on ``fmu``; return (best, mean) seconds per simulation, last y."""
    import fmpy
    import numpy as np
    from fmpy.model_description import read_model_description

    md = read_model_description(str(fmu))
    folder = work / (fmu.stem + "_x")
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    lib = folder / "binaries" / fmpy.platform / (md.coSimulation.modelIdentifier + ".so")
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    data = work / (fmu.stem + ".bin")
    with open(data, "wb") as f:
        f.write(np.int64(t.size).tobytes())
        f.write(np.ascontiguousarray(t, dtype=np.float64).tobytes())
        if inputs:
            f.write(np.ascontiguousarray(u, dtype=np.float64).tobytes())
    args = [str(exe), str(lib), md.guid, (folder / "resources").as_uri(), str(data)]
    args += [str(len(inputs)), str(len(outputs))]
    args += [str(vrs[n]) for n in inputs] + [str(vrs[n]) for n in outputs] + [str(repeats)]
    proc = subprocess.run(args, capture_output=True, text=True, check=True)
    best, mean, last = (float(x) for x in proc.stdout.split())
    return best, mean, last


def timeit(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    """Return (best, median) wall seconds of ``fn`` over ``repeats`` calls (after one warm-up)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), statistics.median(times)


def cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1
