# cmake -DIN=foresight_msgs.idl -DOUT=foresight_interop.idl -P literal_bounds.cmake
#
# The same IDL with every module constant used as a string or sequence bound
# replaced by its value: fastddsgen 2.3.0 (Debian 12) declares the constants
# in the module but refers to them unqualified in the generated member
# functions defined outside it, which does not compile (its bug, not the
# IDL's). Everything else is the protocol's IDL unchanged.
file(READ ${IN} idl)
string(REGEX MATCHALL "const unsigned long [A-Z_]+ = [0-9]+" constants "${idl}")
foreach(c IN LISTS constants)
  string(REGEX REPLACE "const unsigned long ([A-Z_]+) = ([0-9]+)" "\\1" name "${c}")
  string(REGEX REPLACE "const unsigned long ([A-Z_]+) = ([0-9]+)" "\\2" value "${c}")
  string(REGEX REPLACE "([<, ])${name}>" "\\1${value}>" idl "${idl}")
endforeach()
file(WRITE ${OUT} "// Generated from foresight_msgs.idl by literal_bounds.cmake: bounds as literals for fastddsgen.\n${idl}")
