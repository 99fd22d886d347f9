// Opens the LibTorch plugin (libdemcal_torch.so) on first use and forwards the libtorch backend's
// training to it.
#include "torch_plugin_abi.hpp"

#include "demcal/smoothing/regression_ensemble.hpp"

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <stdexcept>
#include <vector>

namespace demcal::smoothing {

namespace {

constexpr const char* kPluginFile = "libdemcal_torch.so";

struct LoadedPlugin {
  std::string path;
  detail::TorchTrainFunction train = nullptr;
  detail::TorchRegressionFunction regression = nullptr;
  std::string error;  // set when no candidate loaded
};

std::vector<std::string> candidate_paths() {
  // A plugin named by the user is the only one tried: a wrong name is an error, not a fallback.
  if (const char* env = std::getenv("DEMCAL_TORCH_PLUGIN"); env && *env) return {env};
  std::vector<std::string> paths;
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    paths.push_back((exe.parent_path() / kPluginFile).string());
    paths.push_back((exe.parent_path() / ".." / "lib" / "demcal" / kPluginFile).lexically_normal().string());
  }
#ifdef DEMCAL_TORCH_PLUGIN_BUILD_PATH
  paths.emplace_back(DEMCAL_TORCH_PLUGIN_BUILD_PATH);
#endif
  return paths;
}

// LibTorch, oneDNN and OpenBLAS choose their kernels by the processor (AVX-512 where it has them,
// else AVX2), and float results differ between those kernels in the last bits. A search that trains a
// network on them (the "mlp" surrogate, objective 2's libtorch smoother) is chaotic in such bits and
// would take another path on another processor. On every processor with AVX2 and FMA the three are
// held to their AVX2 kernels (OpenBLAS's Zen set, the project's reference machines'), so a campaign
// repeats bit for bit across such processors. Set before the libraries load; a value the user set wins.
void hold_kernels_to_avx2() {
#if defined(__x86_64__)
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) return;
  setenv("ATEN_CPU_CAPABILITY", "avx2", 0);
  setenv("ONEDNN_MAX_CPU_ISA", "AVX2", 0);
  setenv("OPENBLAS_CORETYPE", "ZEN", 0);
#endif
}

LoadedPlugin load_plugin() {
  hold_kernels_to_avx2();
  LoadedPlugin plugin;
  std::string tried;
  for (const auto& path : candidate_paths()) {
    if (!std::filesystem::exists(path)) {
      tried += "\n  " + path + ": no such file";
      continue;
    }
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      const char* why = dlerror();
      tried += "\n  " + path + ": " + (why ? why : "dlopen failed");
      continue;
    }
    auto abi = reinterpret_cast<detail::TorchPluginAbiFunction>(dlsym(handle, "demcal_torch_plugin_abi"));
    auto train = reinterpret_cast<detail::TorchTrainFunction>(dlsym(handle, "demcal_torch_train"));
    auto regression = reinterpret_cast<detail::TorchRegressionFunction>(dlsym(handle, "demcal_torch_train_regression"));
    if (!abi || !train || !regression) {
      tried += "\n  " + path + ": not a demcal LibTorch plugin (entry points missing)";
      dlclose(handle);
      continue;
    }
    if (abi() != detail::kTorchPluginAbi) {
      tried += "\n  " + path + ": plugin interface " + std::to_string(abi()) + ", this program needs " +
               std::to_string(detail::kTorchPluginAbi) + " (a plugin from another build)";
      dlclose(handle);
      continue;
    }
    plugin.path = path;
    plugin.train = train;  // the handle stays open for the life of the process
    plugin.regression = regression;
    return plugin;
  }
  const char* env = std::getenv("DEMCAL_TORCH_PLUGIN");
  plugin.error = std::string("LibTorch training needs the plugin ") + kPluginFile +
                 ", and none could be loaded; searched" + (env && *env ? " (as $DEMCAL_TORCH_PLUGIN says)" : "") +
                 ":" + tried;
  return plugin;
}

const LoadedPlugin& plugin() {
  static const LoadedPlugin loaded = load_plugin();  // thread-safe, once per process
  if (!loaded.train) throw std::runtime_error(loaded.error);
  return loaded;
}

// LibTorch's products call the system BLAS, which may not be safe to call from two threads at once
// (Debian's serial OpenBLAS): every training in the process takes its turn.
std::mutex& training_mutex() {
  static std::mutex m;
  return m;
}

}  // namespace

std::string libtorch_plugin_path() { return plugin().path; }

std::vector<float> train_regression_ensemble(const RegressionBatch& b) {
  const std::int64_t parameters = regression_parameter_count(b.inputs, b.outputs, b.hidden_layers, b.hidden_width);
  auto size = [](std::int64_t a, std::int64_t c) { return static_cast<std::size_t>(a * c); };
  if (b.members < 1 || b.rows < 1 || b.inputs < 1 || b.outputs < 1 || b.hidden_layers < 1 || b.hidden_width < 1 ||
      b.epochs < 1 || b.threads < 1 || b.x.size() != size(b.rows, b.inputs) || b.y.size() != size(b.rows, b.outputs) ||
      b.row_weight.size() != size(b.members, b.rows) || b.initial_parameters.size() != size(b.members, parameters))
    throw std::invalid_argument("train_regression_ensemble: the batch's sizes disagree");
  if (b.backend == RegressionBackend::native) return detail::train_regression_native(b);
  std::vector<float> trained;
  std::string error;
  const std::lock_guard<std::mutex> one_at_a_time(training_mutex());
  if (plugin().regression(&b, &trained, &error) != 0)
    throw std::runtime_error("LibTorch regression ensemble: " + error);
  return trained;
}

namespace detail {

TrainingOutput train_libtorch(const TrainingBatch& batch, const SmootherOptions& options) {
  TrainingOutput output;
  std::string error;
  const std::lock_guard<std::mutex> one_at_a_time(training_mutex());
  if (plugin().train(&batch, &options, &output, &error) != 0)
    throw std::runtime_error("libtorch smoother backend: " + error);
  return output;
}

}  // namespace detail

}  // namespace demcal::smoothing
