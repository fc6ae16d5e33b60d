# Writes OUT, a C++ file defining mcstat::detail::kBuiltinOcioConfig with the text of IN.
file(READ "${IN}" _text)
file(WRITE "${OUT}" "// Generated from color/config.ocio; do not edit.\nnamespace mcstat::detail {\nextern const char* const kBuiltinOcioConfig;\nconst char* const kBuiltinOcioConfig = R\"mcstat_ocio(${_text})mcstat_ocio\";\n}\n")
