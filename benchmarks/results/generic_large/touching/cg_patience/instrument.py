"""Run the 10⁵ touching bed's 10-digit path with the CG solves recorded; stop at the first
double-double fallback, dumping the failing solve's componentwise picture."""
import json, os, sys, time
import numpy as np
import scipy.sparse as sp
import rfverify
from rfverify.extended import mixed, krylov

LOG = open("/tmp/big/cg.jsonl", "w")
orig = mixed.restarted_conjugate_gradients
last = {}

def wrapped(Ap, Ai, A, bh, bl, pre, target, good_enough, **kw):
    t = time.perf_counter()
    out = orig(Ap, Ai, A, bh, bl, pre, target, good_enough, **kw)
    rec = {"t": time.perf_counter() - t, "backward": out.backward, "steps": out.steps, "norm": out.residual_norm,
           "stop_norm": kw.get("stop_norm"), "target": target, "good_enough": good_enough,
           "b_inf": float(np.max(np.abs(bh))), "recycled": kw.get("recycled") is not None,
           "product": kw.get("product") is not None}
    if not out.backward <= good_enough:
        n = Ap.size - 1
        xh, xl = out.x
        rh, rl = np.empty(n), np.empty(n)
        krylov.symmetric_residual(n, Ap, Ai, A[0], A[1], bh, bl, xh, xl, rh, rl, np.zeros(n))
        cols = np.repeat(np.arange(n), np.diff(Ap))
        U = sp.csc_matrix((np.abs(A[0]), Ai, Ap), shape=(n, n))
        absA = U + sp.triu(U, 1).T
        denom = absA @ np.abs(xh) + np.abs(bh)
        ratio = np.abs(rh) / np.where(denom > 0, denom, np.inf)
        order = np.argsort(-ratio)[:20]
        rec.update(worst=[(int(i), float(ratio[i]), float(rh[i]), float(denom[i]), float(bh[i]), float(xh[i]))
                          for i in order],
                   above_1e20=int(np.sum(ratio > 1e-20)), above_1e12=int(np.sum(ratio > 1e-12)),
                   normwise=float(np.max(np.abs(rh)) / max(float(np.max(np.abs(bh))), 1e-300)),
                   x_inf=float(np.max(np.abs(xh))), zero_b=int(np.sum(bh == 0)))
    LOG.write(json.dumps(rec) + "\n"); LOG.flush()
    return out

mixed.restarted_conjugate_gradients = wrapped
orig_fb = mixed._RefinedFloat64Factor._fall_back

def fb(self, reason):
    LOG.write(json.dumps({"fallback": reason, "factorisations": self.factorisations}) + "\n"); LOG.flush()
    os._exit(0)

mixed._RefinedFloat64Factor._fall_back = fb
p = rfverify.load(sys.argv[1])
rfverify.solve_to_digits(p, digits=10, progress=lambda m: print(m, file=sys.stderr, flush=True))
