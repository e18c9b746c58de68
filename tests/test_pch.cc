// The translation unit that carries tests/test_pch.h's precompiled form
// (holo_test_pch in tests/CMakeLists.txt); it defines nothing.
