# bench/heat_control_pyadjoint.py — examples/heat_control.lua's discrete problem in pyadjoint
# 2023.0.0.post0 on legacy FEniCS (Debian's python3-dolfin), for the whole optimization side
# by side (issue 55): the heat equation u_t - nu Δu = f_k by backward Euler on an N² P1 mesh,
# u = 0 on the boundary, u(0) = 0, dt = 0.1, T = 2, a control per step time f_0 .. f_N (as
# lugal's per-step control: step k reads f_k), and
#   J = sum_k w_k [1/2 ∫(u_k - d_k)² + alpha/2 ∫((f_k - f_{k-1})/dt)²],  f_{-1} = f_0,
# w the trapezoidal weights (dt/2 at t0 and T, dt between), d = 16 x(1-x) y(1-y) sin(pi t).
# Minimized by scipy's L-BFGS-B through pyadjoint from f = 0; prints the time, the iterations
# and J*.
#   PYTHONPATH=/opt/pyadjoint python3 bench/heat_control_pyadjoint.py N [gtol]
import sys, time, resource
from fenics import *
from fenics_adjoint import *
set_log_level(LogLevel.ERROR)
N = int(sys.argv[1]) if len(sys.argv) > 1 else 8
gtol = float(sys.argv[2]) if len(sys.argv) > 2 else 1e-12
parameters["form_compiler"]["optimize"] = True
parameters["form_compiler"]["cpp_optimize"] = True
nu, dt, T, alpha = 1e-5, 0.1, 2.0, 0.1
steps = int(round(T / dt))
mesh = UnitSquareMesh(N, N)
V = FunctionSpace(mesh, "CG", 1)
X = SpatialCoordinate(mesh)
bc = DirichletBC(V, 0, "on_boundary")
u, v = TrialFunction(V), TestFunction(V)
tc = Constant(0.0)
d = 16*X[0]*(1 - X[0])*X[1]*(1 - X[1])*sin(pi*tc)
ctrls = [Function(V, name="f%d" % k) for k in range(steps + 1)]

def J_of(ctrls):
    u0 = Function(V)
    uh = Function(V)
    f = Function(V)
    a = u*v*dx + dt*nu*inner(grad(u), grad(v))*dx
    L = u0*v*dx + dt*f*v*dx
    J = 0
    for k in range(steps + 1):
        tc.assign(k*dt)
        w = 0.5*dt if k in (0, steps) else dt
        if k > 0:
            f.assign(ctrls[k])
            solve(a == L, uh, bc)
            u0.assign(uh)
        fp = ctrls[k - 1] if k > 0 else ctrls[0]
        J += w*assemble(0.5*(u0 - d)**2*dx + alpha/2*((ctrls[k] - fp)/dt)**2*dx)
    return J

t0 = time.perf_counter()
J = J_of(ctrls)
rf = ReducedFunctional(J, [Control(c) for c in ctrls])
its = [0]
def cb(xk):
    its[0] += 1
fopt = minimize(rf, method="L-BFGS-B", tol=1e-30, callback=cb,
                options={"gtol": gtol, "ftol": 1e-30, "maxiter": 2000, "maxfun": 4000, "maxls": 50})
Jopt = rf(fopt)
t1 = time.perf_counter()
print("heat_control pyadjoint N=%d: L-BFGS-B %d iterations, %.2f s (taping included), J* %.12e, peak RSS %.0f MB"
      % (N, its[0], t1 - t0, Jopt, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024))
