-- expect: lg.parameter: argument 2 (the value of k) must be a finite number
local lg = require "lugal"
local k = lg.parameter("k", 0 / 0)
