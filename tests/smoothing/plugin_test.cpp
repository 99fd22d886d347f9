// LibTorch is a plugin opened on first use: programs that train no network never load it, the
// libtorch backend finds the plugin, and a missing plugin is reported with the places searched.
#include "demcal/smoothing/smoother.hpp"
#include "demcal/smoothing/synthetic.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>

using namespace demcal::smoothing;

namespace {

bool libtorch_mapped() {
  std::ifstream maps("/proc/self/maps");
  std::stringstream text;
  text << maps.rdbuf();
  return text.str().find("libtorch_cpu") != std::string::npos;
}

std::string command_output(const std::string& command, int* status) {
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  std::string out;
  std::array<char, 4096> buf{};
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0;) out.append(buf.data(), n);
  const int s = pclose(pipe);
  *status = WIFEXITED(s) ? WEXITSTATUS(s) : -1;
  return out;
}

XYSeries small_curve() {
  SyntheticCurveOptions o;
  o.samples = 120;
  return make_synthetic_curve(o).noisy;
}

}  // namespace

TEST(LibTorchPlugin, NativeTrainingLeavesLibTorchUnloadedAndLibTorchTrainingLoadsIt) {
  SmootherOptions o;
  o.epochs = 20;
  o.backend = SmootherBackend::native;
  ASSERT_FALSE(libtorch_mapped()) << "LibTorch was loaded before any network was trained";
  EXPECT_EQ(smooth_batch({small_curve()}, o)[0].status, SmoothStatus::ok);
  EXPECT_FALSE(libtorch_mapped()) << "the native backend loaded LibTorch";
  o.backend = SmootherBackend::libtorch;
  EXPECT_EQ(smooth_batch({small_curve()}, o)[0].status, SmoothStatus::ok);
  EXPECT_TRUE(libtorch_mapped());
  EXPECT_NE(libtorch_plugin_path().find("libdemcal_torch.so"), std::string::npos);
}

// On a processor with AVX2 and FMA, opening the plugin holds LibTorch, oneDNN and OpenBLAS to their
// AVX2 kernels (so that a network's training, and every search that uses it, repeats across such
// processors); a value already in the environment is kept.
TEST(LibTorchPlugin, KernelsAreHeldToAvx2WhereTheProcessorHasIt) {
  const std::array<std::array<const char*, 2>, 3> held = {
      {{"ATEN_CPU_CAPABILITY", "avx2"}, {"ONEDNN_MAX_CPU_ISA", "AVX2"}, {"OPENBLAS_CORETYPE", "ZEN"}}};
  std::array<std::string, 3> before;
  for (std::size_t i = 0; i < held.size(); ++i)
    if (const char* v = std::getenv(held[i][0])) before[i] = v;
  EXPECT_NE(libtorch_plugin_path().find("libdemcal_torch.so"), std::string::npos);
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma"))
    GTEST_SKIP() << "no AVX2 and FMA: every library keeps its own choice";
  for (std::size_t i = 0; i < held.size(); ++i) {
    const char* now = std::getenv(held[i][0]);
    ASSERT_NE(now, nullptr) << held[i][0];
    EXPECT_EQ(std::string(now), before[i].empty() ? held[i][1] : before[i]) << held[i][0];
  }
}

TEST(LibTorchPlugin, DemcalProgramDoesNotLinkLibTorch) {
  int status = 0;
  const std::string libraries = command_output(std::string("ldd ") + DEMCAL_BINARY, &status);
  ASSERT_EQ(status, 0) << libraries;
  EXPECT_EQ(libraries.find("libtorch"), std::string::npos) << libraries;
  EXPECT_EQ(libraries.find("libc10"), std::string::npos) << libraries;
}

TEST(LibTorchPlugin, MissingPluginIsReportedWithThePlacesSearched) {
  const std::string dir = ::testing::TempDir();
  const std::string csv = dir + "/plugin_test_curve.csv";
  {
    std::ofstream out(csv);
    out << "displacement,force\n";
    const auto c = small_curve();
    for (std::size_t i = 0; i < c.x.size(); ++i) out << c.x[i] << "," << c.y[i] << "\n";
  }
  int status = 0;
  const std::string out = command_output("DEMCAL_TORCH_PLUGIN=/nonexistent/libdemcal_torch.so " +
                                             std::string(DEMCAL_BINARY) + " smooth " + csv + " --out " + dir +
                                             "/plugin_test_out.csv --backend libtorch",
                                         &status);
  EXPECT_NE(status, 0);
  EXPECT_NE(out.find("/nonexistent/libdemcal_torch.so: no such file"), std::string::npos) << out;
  EXPECT_NE(out.find("DEMCAL_TORCH_PLUGIN"), std::string::npos) << out;
}
