// Opens the LibTorch plugin (libdemcal_torch.so) on first use and forwards the libtorch backend's
// training to it.
#include "torch_plugin_abi.hpp"

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <vector>

namespace demcal::smoothing {

namespace {

constexpr const char* kPluginFile = "libdemcal_torch.so";

struct LoadedPlugin {
  std::string path;
  detail::TorchTrainFunction train = nullptr;
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

LoadedPlugin load_plugin() {
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
    if (!abi || !train) {
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
    return plugin;
  }
  const char* env = std::getenv("DEMCAL_TORCH_PLUGIN");
  plugin.error = std::string("the libtorch smoother backend needs the plugin ") + kPluginFile +
                 ", and none could be loaded; searched" + (env && *env ? " (as $DEMCAL_TORCH_PLUGIN says)" : "") +
                 ":" + tried;
  return plugin;
}

const LoadedPlugin& plugin() {
  static const LoadedPlugin loaded = load_plugin();  // thread-safe, once per process
  if (!loaded.train) throw std::runtime_error(loaded.error);
  return loaded;
}

}  // namespace

std::string libtorch_plugin_path() { return plugin().path; }

namespace detail {

TrainingOutput train_libtorch(const TrainingBatch& batch, const SmootherOptions& options) {
  TrainingOutput output;
  std::string error;
  if (plugin().train(&batch, &options, &output, &error) != 0)
    throw std::runtime_error("libtorch smoother backend: " + error);
  return output;
}

}  // namespace detail

}  // namespace demcal::smoothing
