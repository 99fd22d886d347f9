// Replays a fuzz target's corpus without libFuzzer: linked with one of the *_fuzz.cpp targets
// (fuzz_replay_<target>, built by GCC with the tests; ctest FuzzReplay.<target>), it calls
// LLVMFuzzerTestOneInput once on every file named, or on every file under a folder named, in
// sorted order:
//
//   fuzz_replay_csv fuzz/corpus/csv [more files or folders]
//
// A target aborts on a broken property and lets unexpected exceptions escape; a sanitizer report
// ends the process. So each input runs in a child process of its own (fork): an exception, an
// abort, a signal, a sanitizer report or a leak fails that input, which is named on stderr, and the
// replay goes on with the next. Exit status 0 only when every input passed and at least one input
// was read.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace fs = std::filesystem;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

// The child's side: one call of the target; exit status 0, or 1 after an unexpected exception
// (std::exit, not _exit: LeakSanitizer checks at exit).
[[noreturn]] void run_one(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  try {
    LLVMFuzzerTestOneInput(bytes.data(), bytes.size());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz replay: unexpected exception: %s\n", e.what());
    std::exit(1);
  } catch (...) {
    std::fprintf(stderr, "fuzz replay: unexpected exception of unknown type\n");
    std::exit(1);
  }
  std::exit(0);
}

// The parent's side: "" when the child passed, else how it ended.
std::string replay(const fs::path& path) {
  std::fflush(nullptr);
  const pid_t child = fork();
  if (child < 0) return std::string("fork failed: ") + std::strerror(errno);
  if (child == 0) run_one(path);
  int status = 0;
  while (waitpid(child, &status, 0) < 0)
    if (errno != EINTR) return std::string("waitpid failed: ") + std::strerror(errno);
  if (WIFSIGNALED(status))
    return std::string("killed by signal ") + strsignal(WTERMSIG(status)) +
           " (a property check's abort, or a sanitizer report above)";
  if (WEXITSTATUS(status) != 0)
    return "exit status " + std::to_string(WEXITSTATUS(status)) + " (an exception, or a sanitizer report above)";
  return "";
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
  int failures = 0;
  for (const auto& path : inputs) {
    const std::string failure = replay(path);
    if (failure.empty()) continue;
    ++failures;
    std::fprintf(stderr, "fuzz replay: FAILED on input %s: %s\n", path.c_str(), failure.c_str());
  }
  std::printf("fuzz replay: %zu inputs, %d failed\n", inputs.size(), failures);
  return failures == 0 ? 0 : 1;
}
