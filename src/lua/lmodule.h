/* lmodule.h — entry point of the `lugal` Lua module */
#ifndef LUGAL_LMODULE_H
#define LUGAL_LMODULE_H
#include <lua.h>
int luaopen_lugal(lua_State *L);
#endif
