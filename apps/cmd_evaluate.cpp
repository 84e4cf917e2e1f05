#include <cstdio>
#include <filesystem>

#include "command.hpp"
#include "seqloc/io/run_folder.hpp"

namespace seqloc::app {
namespace {

// seqloc evaluate: the recall table again, from the poses.csv files of localize outputs.
class EvaluateCommand : public Command {
 public:
  void setup(CLI::App& app) override {
    app.add_option("outputs", outs_,
                   "Folders of seqloc localize output: a whole output folder, a route's folder or a mode's folder "
                   "(any mix; a file reached twice counts once)")
        ->required();
  }

  int run() override {
    const io::MetricsByMode metrics = io::evaluate_poses_files(io::find_poses_files(outs_));
    std::fputs(io::format_table(metrics).c_str(), stdout);
    return kExitOk;
  }

 private:
  std::vector<std::filesystem::path> outs_;
};

}  // namespace

std::unique_ptr<Command> make_evaluate_command() { return std::make_unique<EvaluateCommand>(); }

}  // namespace seqloc::app
