-- Every message the Lua layer formats goes through lua_pushfstring's own conversions (%s %d
-- %I %f %p %c %U %%: no flags, widths, precisions or length modifiers). Six error paths once
-- printed Lua's "invalid option '%l' to 'lua_pushfstring'" instead of their message (%ld,
-- %.0f). This scans src/lua/*.c for luaL_error, lua_pushfstring and luaL_argerror calls and
-- fails on any other conversion; and checks one of the fixed messages by running it.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local root = arg[0]:match("(.*/)tests/lua/") or "./"
local files = {"largs.c", "lexpr.c", "lmesh.c", "lmodule.c", "loperator.c", "lopt.c", "lparallel.c", "lproblem.c", "lrepair.c", "ltime.c",
               "launch.c", "main.c"}
local bad, calls = {}, 0
-- every call of fn in the file s: its string literals (concatenated, as C does) checked
local function scan(f, s, fn)
  for at, args in s:gmatch("()" .. fn .. "%s*(%b())") do
    calls = calls + 1
    local lits = {}
    for lit in args:gmatch('"(.-[^\\])"') do lits[#lits + 1] = lit end
    for spec in table.concat(lits):gmatch("%%([^%a%%]*%a?)") do
      if not spec:match("^[sdIfpcU]$") then
        local line = select(2, s:sub(1, at):gsub("\n", "")) + 1
        bad[#bad + 1] = string.format("src/lua/%s:%d: %%%s", f, line, spec)
      end
    end
  end
end
for _, f in ipairs(files) do
  local s = T.slurp(root .. "src/lua/" .. f)
  scan(f, s, "luaL_error")
  scan(f, s, "lua_pushfstring")
end
T.check(calls > 300, "only %d formatting calls found: the scan is broken", calls)
T.check(#bad == 0, "conversions lua_pushfstring does not have:\n%s", table.concat(bad, "\n"))
-- a fixed message, run: an array of the wrong length for mesh:write's cell field
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 2}
T.fails(function() mesh:write(os.tmpname() .. ".svg", {q = {1, 2}}) end, "or 8 numbers (one per cell)")
print(string.format("%d formatting calls, every conversion one lua_pushfstring has", calls))
