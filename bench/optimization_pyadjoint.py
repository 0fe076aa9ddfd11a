# bench/optimization_pyadjoint.py CASE N — the pyadjoint side of bench/optimization.lua:
# the same problems on legacy FEniCS (Debian python3-dolfin) with pyadjoint 2023.0.0.post0
# (fenics_adjoint; pure Python, put on PYTHONPATH by bench/run.sh, never a dependency of
# lugal). CPU time (time.process_time), form compilation warmed by a first evaluation.
#   CASE mother | mother0 | nonlinear | inversion, as in bench/optimization.lua
# Prints one line per measurement, in the same format as the lugal side.
import sys
import time
import statistics
from fenics import *
from fenics_adjoint import *

set_log_level(LogLevel.ERROR)
case = sys.argv[1] if len(sys.argv) > 1 else "mother"
N = int(sys.argv[2]) if len(sys.argv) > 2 else 32
assert case in ("mother", "mother0", "nonlinear", "inversion")
lu = {"linear_solver": "mumps"}
newton = {"newton_solver": {"linear_solver": "mumps", "relative_tolerance": 1e-10, "absolute_tolerance": 1e-12}}

mesh = UnitSquareMesh(N, N)          # right diagonals, as lg.mesh.rectangle
V = FunctionSpace(mesh, "CG", 1)
X = SpatialCoordinate(mesh)
bc = DirichletBC(V, 0.0, "on_boundary")
v = TestFunction(V)
beta, kmin = 1e-8, 1.0

if case == "inversion":
    with stop_annotating():
        kt = interpolate(Expression("1 + exp(-40*((x[0]-0.4)*(x[0]-0.4) + (x[1]-0.6)*(x[1]-0.6)))", degree=4), V)
        w = TrialFunction(V)
        ut = Function(V)
        solve(kt * inner(grad(w), grad(v)) * dx == v * dx, ut, bc, solver_parameters=lu)
        peak = abs(ut.vector().get_local()).max()
        uobs = interpolate(Expression("0.01*peak*sin(37*x[0])*cos(23*x[1])", peak=peak, degree=4), V)
        uobs.vector()[:] += ut.vector()


def build():
    """a new tape: the forward run that pyadjoint records"""
    set_working_tape(Tape())
    u = Function(V)
    if case == "inversion":
        k = interpolate(Constant(1.0), V)
        w = TrialFunction(V)
        solve(k * inner(grad(w), grad(v)) * dx == v * dx, u, bc, solver_parameters=lu)
        J = assemble(0.5 * (u - uobs) ** 2 * dx + beta / 2 * inner(grad(k), grad(k)) * dx)
        return ReducedFunctional(J, Control(k)), k
    f = Function(FunctionSpace(mesh, "DG", 0) if case == "mother0" else V)
    d = sin(pi * X[0]) * sin(pi * X[1]) / (2 * pi ** 2)
    if case == "nonlinear":
        F = (1 + u ** 2) * inner(grad(u), grad(v)) * dx - f * v * dx
        solve(F == 0, u, bc, solver_parameters=newton)
    else:
        w = TrialFunction(V)
        solve(inner(grad(w), grad(v)) * dx == f * v * dx, u, bc, solver_parameters=lu)
    J = assemble(0.5 * (u - d) ** 2 * dx + 1e-6 / 2 * f ** 2 * dx)
    return ReducedFunctional(J, Control(f)), f


cpu = time.process_time
C = FunctionSpace(mesh, "DG", 0) if case == "mother0" else V
m = interpolate(Expression("1 + 0.3*x[0]*x[1]" if case == "inversion" else "1 + x[0]", degree=2), C)
dm = interpolate(Expression("sin(pi*x[0])*sin(pi*x[1])", degree=4), C)
rf, _ = build()
rf(m); rf.derivative(); rf.hessian(dm)           # compiles every form once
ts, tg, th = [], [], []
for _ in range(3):
    rf, _ = build()
    c = cpu(); rf(m); ts.append(cpu() - c)
    c = cpu(); rf.derivative(); tg.append(cpu() - c)
    c = cpu(); rf.hessian(dm); th.append(cpu() - c)
s = statistics.median(ts)
print("pyadjoint %s %d: state %.4f s, gradient %.4f s (%.2fx state), Hessian action %.4f s (%.2fx state)"
      % (case, N, s, statistics.median(tg), statistics.median(tg) / s, statistics.median(th), statistics.median(th) / s))

# the whole optimization from the initial control, scipy's L-BFGS-B (the dof-vector inner
# product), stopped when the largest gradient entry falls to 1e-8 (1e-6 for the inversion)
# of its initial value, as lugal's gttol (lugal measures it in the L2 norm)
rf, ctl = build()
g0 = abs(rf.derivative().vector().get_local()).max()
its = [0]
evals = [0]


def count(j, *args):
    evals[0] += 1
    return j


rf.eval_cb_post = count
c = cpu()
bounds = (kmin, 1e10) if case == "inversion" else None
rtol = 1e-6 if case == "inversion" else 1e-8
mopt = minimize(rf, method="L-BFGS-B", bounds=bounds, tol=None,
                options={"gtol": rtol * g0, "ftol": 0.0, "maxiter": 2000, "maxfun": 10000, "disp": False},
                callback=lambda xk: its.__setitem__(0, its[0] + 1))
t = cpu() - c
print("pyadjoint %s %d: optimization L-BFGS-B %.3f s, %d iterations, %d evaluations, J* = %.10e"
      % (case, N, t, its[0], evals[0], rf(mopt)))
