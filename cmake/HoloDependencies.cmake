# Every dependency is a Debian package installed by scripts/setup.sh.
find_package(Threads REQUIRED)
find_package(PkgConfig REQUIRED)
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(OpenCV REQUIRED COMPONENTS core imgproc imgcodecs video features2d calib3d)
find_package(OpenMesh REQUIRED)
find_package(yaml-cpp REQUIRED)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)
# Log lines of every program and library (common/log.h); compiled, fmt external.
find_package(spdlog 1.10 REQUIRED)
if(HOLO_BUILD_TESTS)
  find_package(GTest REQUIRED)
  include(GoogleTest)
endif()
# Wire protocol codecs (protocol/): LZ4 and zstd, meshoptimizer's vertex and
# index codecs, libturbojpeg; Draco as the geometry peer in benchmarks.
pkg_check_modules(LZ4 REQUIRED IMPORTED_TARGET liblz4)
pkg_check_modules(ZSTD REQUIRED IMPORTED_TARGET libzstd)
pkg_check_modules(TURBOJPEG REQUIRED IMPORTED_TARGET libturbojpeg)
pkg_check_modules(LIBJPEG REQUIRED IMPORTED_TARGET libjpeg)  # C1 encoder: own quantization tables
find_package(meshoptimizer REQUIRED)
find_package(draco REQUIRED)
# Video colour (V1, protocol/video_codec.h): libavcodec with Debian's libx264,
# libvpx, SVT-AV1 and dav1d.
pkg_check_modules(AVCODEC REQUIRED IMPORTED_TARGET libavcodec)
pkg_check_modules(AVUTIL REQUIRED IMPORTED_TARGET libavutil)
# Spatial voice (audio/): Opus and OpenAL Soft.
pkg_check_modules(OPUS REQUIRED IMPORTED_TARGET opus)
find_package(OpenAL REQUIRED)

# Ceres (non-rigid tracking solver).
find_package(Ceres REQUIRED)

# Asio is header-only and standalone in Debian (no CMake config).
find_path(ASIO_INCLUDE_DIR asio.hpp REQUIRED)
add_library(holo_asio INTERFACE)
target_include_directories(holo_asio SYSTEM INTERFACE ${ASIO_INCLUDE_DIR})
target_compile_definitions(holo_asio INTERFACE ASIO_STANDALONE ASIO_NO_DEPRECATED)
target_link_libraries(holo_asio INTERFACE Threads::Threads)
find_package(OpenSSL REQUIRED)

# Rendering: GLFW window or EGL surfaceless context; GL and EGL functions via
# libepoxy, which loads libGL/libEGL itself at run time (nothing links them).
# epoxy/egl.h includes the Khronos EGL/eglplatform.h (libegl-dev).
find_package(glfw3 3.3 REQUIRED)
pkg_check_modules(EPOXY REQUIRED IMPORTED_TARGET epoxy)
find_path(EGL_PLATFORM_INCLUDE_DIR EGL/eglplatform.h REQUIRED)
# Resampling of voice input to 48 kHz (audio/).
pkg_check_modules(SOXR REQUIRED IMPORTED_TARGET soxr)
# Capture-side echo cancellation and noise suppression (audio/echo_canceller):
# speexdsp and WebRTC's audio processing module, compared in the audio bench.
pkg_check_modules(SPEEXDSP REQUIRED IMPORTED_TARGET speexdsp)
pkg_check_modules(WEBRTC_APM REQUIRED IMPORTED_TARGET webrtc-audio-processing)
# Personal HRTFs from SOFA files (audio/sofa_hrtf).
pkg_check_modules(MYSOFA REQUIRED IMPORTED_TARGET libmysofa)
