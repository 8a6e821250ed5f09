// vdbsurf: one binary, one subcommand per job; each subcommand is a thin shell over the library.
#include "cli_common.h"

#include "vdbsurf/core/cancel.h"

int main(int argc, char** argv) {
    using namespace vdbsurf;
    CLI::App app{"vdbsurf " VDBSURF_VERSION ": implicit shapes and VDB volumes to surfaces"};
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("vdbsurf ") + VDBSURF_VERSION);
    app.add_flag("-q,--quiet", cli::globals().quiet, "Print only errors");
    app.fallthrough();

    std::vector<std::pair<CLI::App*, cli::Action>> commands;
    auto add = [&](cli::Action (*make)(CLI::App&)) {
        const std::size_t before = app.get_subcommands({}).size();
        cli::Action action = make(app);
        commands.emplace_back(app.get_subcommands({})[before], std::move(action));
    };
    add(&cli::addInfoCommand);
    add(&cli::addMeshCommand);
    add(&cli::addCompareCommand);
    add(&cli::addRasterizeCommand);
    add(&cli::addEditCommand);
    add(&cli::addSubdivideCommand);
    add(&cli::addPatchesCommand);

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    }
    installSignalCancel();
    for (auto& [sub, action] : commands)
        if (sub->parsed()) return cli::runGuarded(action, sub->get_name());
    return 2;
}
