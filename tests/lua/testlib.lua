-- testlib.lua — helpers for lugal's Lua tests: checks that raise errors with a message
-- naming what was expected, and rate computations.
local T = {}
T.failed = 0

function T.check(cond, fmt, ...)
  if not cond then error(string.format(fmt or "check failed", ...), 2) end
end

function T.close(a, b, tol, what)
  tol = tol or 1e-12
  if not (math.abs(a - b) <= tol * (1 + math.abs(b))) then
    error(string.format("%s: got %.17g, expected %.17g (tol %g)", what or "value", a, b, tol), 2)
  end
end

-- the call must fail with a message containing each of the given fragments
function T.fails(fn, ...)
  local ok, msg = pcall(fn)
  if ok then error("expected an error, but the call succeeded", 2) end
  msg = tostring(msg)
  for _, frag in ipairs{...} do
    if not msg:find(frag, 1, true) then
      error(string.format("error message %q does not contain %q", msg, frag), 2)
    end
  end
  return msg
end

function T.rate(e1, e2, h1, h2) return math.log(e1 / e2) / math.log(h1 / h2) end

-- the output (stdout and stderr) of this test script run again by the same lugal with the
-- given arguments, before them environment assignments ("OMP_NUM_THREADS=2") if given
function T.child(args, env)
  local h = io.popen(string.format("%s'%s' '%s' %s 2>&1", env and env .. " " or "", arg[-1], arg[0], args or ""))
  local out = h:read("a")
  h:close()
  return out
end

return T
