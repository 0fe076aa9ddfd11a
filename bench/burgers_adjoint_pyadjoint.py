# bench/burgers_adjoint_pyadjoint.py — bench/burgers_adjoint.lua's problem in pyadjoint
# 2023.0.0.post0 on legacy FEniCS (Debian's python3-dolfin): viscous Burgers by backward
# Euler, P1 on N cells, Newton at every step (solve(F == 0), its default tolerances), a source
# constant in time as the control, J = 1/2 ∫ (u(T) - d)² + alpha/2 ∫∫ f² (the trapezoidal
# rule over the step times, as lugal's running terms). Prints the taped forward run, the
# gradient (compute_gradient), their ratio and the peak resident memory.
#   PYTHONPATH=/opt/pyadjoint python3 bench/burgers_adjoint_pyadjoint.py N steps
import sys, time, resource
from fenics import *
from fenics_adjoint import *
set_log_level(LogLevel.ERROR)
N = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
steps = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
parameters["form_compiler"]["optimize"] = True
parameters["form_compiler"]["cpp_optimize"] = True
T, nu, alpha = 0.5, 0.01, 1e-4
dt = T / steps
mesh = UnitIntervalMesh(N)
V = FunctionSpace(mesh, "CG", 1)
f = interpolate(Expression("0.1*x[0]", degree=1), V)
d = interpolate(Expression("0.3*sin(2*pi*x[0])", degree=3), V)
bc = DirichletBC(V, 0, "on_boundary")
v = TestFunction(V)
def run(f):
    u0 = interpolate(Expression("sin(pi*x[0])", degree=3), V)
    u = Function(V)
    u.assign(u0)
    F = (u - u0)/dt*v*dx + u*u.dx(0)*v*dx + nu*inner(grad(u), grad(v))*dx - f*v*dx
    J = assemble(alpha/2*f**2*dx)*(0.5*dt)
    for k in range(1, steps + 1):
        solve(F == 0, u, bc)
        u0.assign(u)
        w = 0.5*dt if k == steps else dt
        J += assemble(alpha/2*f**2*dx)*w
    J += assemble(0.5*(u - d)**2*dx)
    return J
compute_gradient(run(f), Control(f))  # forms compiled, the adjoint's too
tape = get_working_tape()
tape.clear_tape()
t0 = time.perf_counter()
J = run(f)
t1 = time.perf_counter()
g = compute_gradient(J, Control(f))
t2 = time.perf_counter()
print("pyadjoint burgers N=%d steps=%d: forward %.3f s, gradient %.3f s (%.2f x the forward), peak RSS %.0f MB, J %.12e"
      % (N, steps, t1 - t0, t2 - t1, (t2 - t1) / (t1 - t0), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, J))
