// Replays a fuzz target's corpus without libFuzzer: linked with one of the *_fuzz.cpp targets
// (fuzz_replay_<target>, built by GCC with the tests; ctest FuzzReplay.<target>), it calls
// LLVMFuzzerTestOneInput once on every file named, or on every file under a folder named, in
// sorted order:
//
//   fuzz_replay_csv fuzz/corpus/csv [more files or folders]
//
// A target aborts on a broken property and lets unexpected exceptions escape. An exception is
// reported with the input's path and the replay goes on; an abort (or a sanitizer report, which
// ends the process) is reported with the input's path from a signal handler or the sanitizer's
// death callback. Exit status 0 only when every input passed and at least one input was read.
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace fs = std::filesystem;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);
// In a sanitized build (ASan/UBSan runtime linked) this names the input before the report ends the
// process; elsewhere the weak symbol is null.
extern "C" void __sanitizer_set_death_callback(void (*callback)(void)) __attribute__((weak));

namespace {

// The input being replayed, for the abort handler and the death callback (async-signal-safe write).
char current_input[4096] = "";

void name_current_input() {
  const char* prefix = "fuzz replay: FAILED on input ";
  const char* suffix = ": the process ends (a property check aborted, or the sanitizer report above)\n";
  (void)!write(STDERR_FILENO, prefix, std::strlen(prefix));
  (void)!write(STDERR_FILENO, current_input, std::strlen(current_input));
  (void)!write(STDERR_FILENO, suffix, std::strlen(suffix));
}

extern "C" void on_abort(int signal) {
  name_current_input();
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

std::vector<fs::path> inputs_of(const std::vector<std::string>& args) {
  std::vector<fs::path> inputs;
  for (const auto& arg : args) {
    if (fs::is_directory(arg)) {
      for (const auto& entry : fs::recursive_directory_iterator(arg))
        if (entry.is_regular_file()) inputs.push_back(entry.path());
    } else if (fs::is_regular_file(arg)) {
      inputs.emplace_back(arg);
    } else {
      std::fprintf(stderr, "fuzz replay: no file or folder %s\n", arg.c_str());
      return {};
    }
  }
  std::sort(inputs.begin(), inputs.end());
  return inputs;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s FILE_OR_FOLDER...\n", argv[0]);
    return 2;
  }
  const auto inputs = inputs_of(std::vector<std::string>(argv + 1, argv + argc));
  if (inputs.empty()) {
    std::fprintf(stderr, "fuzz replay: no input to replay\n");
    return 2;
  }
  std::signal(SIGABRT, on_abort);
  if (__sanitizer_set_death_callback) __sanitizer_set_death_callback(name_current_input);
  int failures = 0;
  for (const auto& path : inputs) {
    std::snprintf(current_input, sizeof current_input, "%s", path.c_str());
    std::ifstream in(path, std::ios::binary);
    const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    try {
      LLVMFuzzerTestOneInput(bytes.data(), bytes.size());
    } catch (const std::exception& e) {
      ++failures;
      std::fprintf(stderr, "fuzz replay: FAILED on input %s: unexpected exception: %s\n", path.c_str(), e.what());
    } catch (...) {
      ++failures;
      std::fprintf(stderr, "fuzz replay: FAILED on input %s: unexpected exception of unknown type\n", path.c_str());
    }
  }
  std::printf("fuzz replay: %zu inputs, %d failed\n", inputs.size(), failures);
  return failures == 0 ? 0 : 1;
}
