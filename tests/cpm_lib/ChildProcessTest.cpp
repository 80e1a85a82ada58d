// cpm::ChildProcess with real programs (/bin/sh): exit codes and signals told apart, stdout
// captured or written to a file, the environment passed on, a child that ignores SIGTERM
// killed after its grace, a whole process group stopped, and clear errors for a program that
// is not there.
#include <cpm/ChildProcess.hpp>
#include <cpm/Error.hpp>

#include <gtest/gtest.h>

#include <csignal>
#include <fstream>
#include <sstream>

#include <unistd.h>

using namespace std::chrono_literals;

namespace {

cpm::ChildProcess sh(const std::string& script, cpm::ProcessOptions o = {})
{
    o.argv = {"/bin/sh", "-c", script};
    return cpm::ChildProcess(std::move(o));
}

}  // namespace

TEST(ChildProcess, TellsAnExitCodeFromASignal)
{
    auto three = sh("exit 3");
    auto end = three.wait(5s);
    ASSERT_TRUE(end);
    EXPECT_EQ(end->code, 3);
    EXPECT_FALSE(end->ok());
    EXPECT_EQ(end->describe(), "exited with code 3");
    EXPECT_FALSE(three.running());

    auto segv = sh("kill -SEGV $$");
    end = segv.wait(5s);
    ASSERT_TRUE(end);
    EXPECT_EQ(end->signal, SIGSEGV);
    EXPECT_EQ(end->describe(), "killed by SIGSEGV");
}

TEST(ChildProcess, CapturesLinesAndPassesTheEnvironment)
{
    auto child = sh("echo first; echo \"value=$CPM_CHILD_TEST\"; printf 'no newline'", {.env = {"CPM_CHILD_TEST=42"}, .capture_stdout = true});
    EXPECT_EQ(child.read_line(), "first");
    EXPECT_EQ(child.read_line(), "value=42");
    EXPECT_EQ(child.read_line(), "no newline");
    EXPECT_EQ(child.read_line(), std::nullopt);
    ASSERT_TRUE(child.wait(5s));
    EXPECT_TRUE(child.ended()->ok());
}

TEST(ChildProcess, WritesItsOutputToFiles)
{
    const std::string out = testing::TempDir() + "child_out.txt", err = testing::TempDir() + "child_err.txt";
    auto child = sh("echo to-out; echo to-err >&2", {.stdout_path = out, .stderr_path = err});
    ASSERT_TRUE(child.wait(5s));
    std::ifstream o(out), e(err);
    std::stringstream os, es;
    os << o.rdbuf();
    es << e.rdbuf();
    EXPECT_EQ(os.str(), "to-out\n");
    EXPECT_EQ(es.str(), "to-err\n");
    ::unlink(out.c_str());
    ::unlink(err.c_str());
}

TEST(ChildProcess, StopKillsAChildThatIgnoresSigtermAfterTheGrace)
{
    auto stubborn = sh("trap '' TERM; echo ready; while :; do sleep 0.05; done", {.capture_stdout = true});
    ASSERT_EQ(stubborn.read_line(), "ready");
    EXPECT_TRUE(stubborn.running());
    const auto end = stubborn.stop(200ms);
    EXPECT_EQ(end.signal, SIGKILL);

    auto polite = sh("echo ready; while :; do sleep 0.05; done", {.capture_stdout = true});
    ASSERT_EQ(polite.read_line(), "ready");
    EXPECT_EQ(polite.stop(5s).signal, SIGTERM);

    // Frozen (SIGSTOP): continued after its SIGTERM, which then ends it, not the SIGKILL.
    auto frozen = sh("echo ready; while :; do sleep 0.05; done", {.capture_stdout = true});
    ASSERT_EQ(frozen.read_line(), "ready");
    frozen.signal(SIGSTOP);
    EXPECT_EQ(frozen.stop(5s).signal, SIGTERM);
}

TEST(ChildProcess, StoppingAProcessGroupEndsTheProgramsItStarted)
{
    auto parent = sh("sleep 30 & echo $!; wait", {.capture_stdout = true, .own_process_group = true});
    const auto grandchild = parent.read_line();
    ASSERT_TRUE(grandchild);
    const pid_t pid = std::stoi(*grandchild);
    EXPECT_EQ(::kill(pid, 0), 0);
    parent.stop(2s);
    // The grandchild was signalled too; it is reaped by init, so wait for it to vanish.
    bool gone = false;
    for (int i = 0; i < 200 && !gone; ++i) {
        gone = ::kill(pid, 0) != 0;
        if (!gone) usleep(10'000);
    }
    EXPECT_TRUE(gone) << "sleep " << pid << " outlived its group";
}

TEST(ChildProcess, TheDestructorStopsAChildStillRunning)
{
    pid_t pid;
    {
        auto child = sh("while :; do sleep 0.05; done");
        pid = child.pid();
        ASSERT_TRUE(child.running());
    }
    EXPECT_NE(::kill(pid, 0), 0);  // ended and reaped
}

TEST(ChildProcess, AMissingProgramIsAnErrorNamingIt)
{
    try {
        cpm::ChildProcess missing({.argv = {"/no/such/program", "--flag"}});
        FAIL() << "started a program that is not there";
    } catch (const cpm::Error& e) {
        EXPECT_STREQ(e.what(), "cannot run /no/such/program: No such file or directory");
    }
    try {
        (void)cpm::sibling_executable("no_such_cpm_program");
        FAIL();
    } catch (const cpm::Error& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind("no_such_cpm_program is not beside this program (" + cpm::executable_dir() + "/no_such_cpm_program: ", 0), 0u)
            << what;
    }
    EXPECT_EQ(cpm::sibling_executable("cpm_lib_unit_tests"), cpm::executable_dir() + "/cpm_lib_unit_tests");
}
