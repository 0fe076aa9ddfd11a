# bench/time_adjoint_pyadjoint.py — bench/time_adjoint.lua's problem in pyadjoint 2023.0.0.post0
# on legacy FEniCS (Debian's python3-dolfin): the heat equation by backward Euler on an N² P1
# mesh, a source constant in time as the control, J = 1/2 ∫ (u(T) - d)² + 1/2 ∫∫ u² (the
# trapezoidal rule over the step times, as lugal's running terms). Prints the taped forward
# run, the gradient (compute_gradient), their ratio and the peak resident memory.
#   PYTHONPATH=/opt/pyadjoint python3 bench/time_adjoint_pyadjoint.py N steps
import sys, time, resource
from fenics import *
from fenics_adjoint import *
set_log_level(LogLevel.ERROR)
N = int(sys.argv[1]) if len(sys.argv) > 1 else 32
steps = int(sys.argv[2]) if len(sys.argv) > 2 else 100
parameters["form_compiler"]["optimize"] = True
parameters["form_compiler"]["cpp_optimize"] = True
mesh = UnitSquareMesh(N, N)
V = FunctionSpace(mesh, "CG", 1)
dt = 1.0 / steps
x = SpatialCoordinate(mesh)
f = interpolate(Expression("1 + x[0]", degree=1), V)
d = interpolate(Expression("x[0]*x[1]", degree=1), V)
bc = DirichletBC(V, 0, "on_boundary")
u, v = TrialFunction(V), TestFunction(V)
def run(f):
    u0 = interpolate(Expression("sin(pi*x[0])*sin(pi*x[1])", degree=3), V)
    a = u*v*dx + dt*0.1*inner(grad(u), grad(v))*dx
    uh = Function(V)
    J = assemble(0.5*u0**2*dx)*(0.5*dt)
    for k in range(1, steps + 1):
        L = u0*v*dx + dt*f*v*dx
        solve(a == L, uh, bc)
        u0.assign(uh)
        w = 0.5*dt if k == steps else dt
        J += assemble(0.5*uh**2*dx)*w
    J += assemble(0.5*(uh - d)**2*dx)
    return J
compute_gradient(run(f), Control(f))  # forms compiled, the adjoint's too
tape = get_working_tape()
tape.clear_tape()
t0 = time.perf_counter()
J = run(f)
t1 = time.perf_counter()
g = compute_gradient(J, Control(f))
t2 = time.perf_counter()
print("pyadjoint N=%d steps=%d: forward %.3f s, gradient %.3f s (%.2f x the forward), peak RSS %.0f MB, J %.12e"
      % (N, steps, t1 - t0, t2 - t1, (t2 - t1) / (t1 - t0), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, J))
