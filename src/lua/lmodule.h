/* lmodule.h — entry point of the `lugal` Lua module */
#ifndef LUGAL_LMODULE_H
#define LUGAL_LMODULE_H
#include <lua.h>
int luaopen_lugal(lua_State *L);
/* the end of a script as a collective call (lparallel.c): the runner calls it after the script */
int lg_lua_end_check(lua_State *L);
#endif
