# cmake -DINPUT=<file.cl> -DOUTPUT=<file.cpp> -DSYMBOL=<function> -P embed_source.cmake
# Writes a C++ function returning the file's text (a raw string literal split in pieces under
# the 64 KiB some compilers allow per literal).
file(READ "${INPUT}" text)
string(LENGTH "${text}" length)
set(out "// Generated from ${INPUT} by kernels/cmake/embed_source.cmake; do not edit.\n")
string(APPEND out "namespace sonoshape::kernels {\nconst char* ${SYMBOL}() {\n  return\n")
set(offset 0)
while(offset LESS length)
  string(SUBSTRING "${text}" ${offset} 16000 piece)
  string(APPEND out "      R\"sonoshape_cl(${piece})sonoshape_cl\"\n")
  math(EXPR offset "${offset} + 16000")
endwhile()
string(APPEND out "      ;\n}\n}  // namespace sonoshape::kernels\n")
file(WRITE "${OUTPUT}" "${out}")
