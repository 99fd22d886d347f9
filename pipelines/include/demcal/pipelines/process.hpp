// Running an external program without a shell: the seam of the external-command evaluation
// backend (users whose simulator is 3DEC, UDEC, YADE or their own script).
//
// No process outlives a run. The program is started by a small supervisor process (a fork of the
// caller, no exec) that is the program's "child subreaper" (Linux PR_SET_CHILD_SUBREAPER): every
// descendant the program leaves behind, including those that call setsid() or double-fork to
// detach, is re-parented to the supervisor instead of to init. When the program ends, times out,
// is cancelled, or the calling process dies (even by SIGKILL: the supervisor watches a pipe whose
// write end only the caller holds), the supervisor kills the program's process group, then kills
// and reaps every remaining descendant until it has no child left, and only then reports. So no
// orphan and no zombie remains. The supervisor sits in its own process group and ignores SIGINT,
// SIGTERM, SIGHUP and SIGQUIT, so that a signal to the caller's group cannot take it down before
// it has cleaned up; the program itself starts with default signal dispositions.
//
// Nothing is interpreted by a shell: the argument template is split on whitespace (single and
// double quotes group words, a backslash escapes the next character) and each `{name}`
// placeholder is replaced inside its word.
#pragma once

#include <atomic>
#include <map>
#include <string>
#include <vector>

namespace demcal::pipelines {

struct ProcessOptions {
  std::vector<std::string> argv;      // argv[0] is the program (found on PATH when it has no '/')
  std::string working_directory;      // "" = the caller's; must exist
  double timeout_s = 0;               // s of wall time; 0 = no limit. On expiry the group gets SIGKILL
  std::string stdout_path;            // "" = discard (/dev/null); else truncated and written
  std::string stderr_path;            // "" = discard
  const std::atomic<bool>* cancel = nullptr;  // raised -> the group is killed (status cancelled)
  // Largest file the program (and its children) may write, in bytes (RLIMIT_FSIZE; covers stdout,
  // stderr and output files); 0 = no limit. A write past it kills the program with SIGXFSZ
  // (status signalled, signal 25) or, if it ignores that signal, fails with EFBIG.
  long long max_file_bytes = 0;
  void Validate() const;              // throws std::invalid_argument naming the bad value
};

enum class ProcessStatus {
  exited,           // ran to its end; see exit_code
  signalled,        // ended by a signal it did not get from us (a crash); see signal
  timed_out,        // killed at timeout_s
  cancelled,        // killed because the cancel flag was raised
  failed_to_start,  // fork/exec failed (missing program, no permission); see message
};
std::string to_string(ProcessStatus status);

struct ProcessResult {
  ProcessStatus status = ProcessStatus::failed_to_start;
  int exit_code = -1;        // valid when status == exited
  int signal = 0;            // valid when status == signalled
  double wall_time_s = 0;
  std::string message;       // one line for people: "exit code 3", "killed after 2 s timeout", ...
  int leftover_processes = 0;  // descendants still running after the program ended (all killed)
  bool ok() const { return status == ProcessStatus::exited && exit_code == 0; }
};

// Runs the program to its end, the timeout or cancellation, then kills whatever it left running
// (see the header comment). Never throws for a failure of the child (that is a status); throws
// std::invalid_argument for bad options. Thread-safe: several runs may go on at once.
ProcessResult run_process(const ProcessOptions& options);

// Splits a command template into words without a shell (see the header comment). Throws
// std::invalid_argument on an unterminated quote or an empty template.
std::vector<std::string> split_command_line(const std::string& command_line);

// Replaces every `{name}` in every word by values.at(name). `{{` and `}}` give literal braces.
// An unknown placeholder or an unterminated brace throws std::invalid_argument naming it.
std::vector<std::string> expand_placeholders(const std::vector<std::string>& words,
                                             const std::map<std::string, std::string>& values);

// The placeholder names used in a template, in order of first appearance.
std::vector<std::string> placeholder_names(const std::vector<std::string>& words);

}  // namespace demcal::pipelines
