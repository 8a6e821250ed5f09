// Recursive-descent parser for formulas, emitting postfix code for a stack machine.
// Grammar (lowest to highest precedence):
//   sum     := product (('+' | '-') product)*
//   product := unary (('*' | '/') unary)*
//   unary   := '-' unary | '+' unary | power
//   power   := primary ('^' unary)?          (right associative; -x^2 is -(x^2))
//   primary := number | x | y | z | pi | name '(' sum (',' sum)* ')' | '(' sum ')'
#include "vdbsurf/core/error.h"
#include "vdbsurf/field/expression.h"

#include <atomic>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <map>
#include <stdexcept>

namespace vdbsurf {

namespace {

struct FunctionSpec {
    ExprOp op;
    int minArgs, maxArgs; // maxArgs < 0: unbounded
};

const std::map<std::string, FunctionSpec>& functions() {
    static const std::map<std::string, FunctionSpec> table = {
        {"abs", {ExprOp::Abs, 1, 1}},   {"sqrt", {ExprOp::Sqrt, 1, 1}}, {"exp", {ExprOp::Exp, 1, 1}},
        {"log", {ExprOp::Log, 1, 1}},   {"sin", {ExprOp::Sin, 1, 1}},   {"cos", {ExprOp::Cos, 1, 1}},
        {"tan", {ExprOp::Tan, 1, 1}},   {"pow", {ExprOp::Pow, 2, 2}},   {"clamp", {ExprOp::Clamp, 3, 3}},
        {"min", {ExprOp::Min, 2, -1}},  {"max", {ExprOp::Max, 2, -1}},
    };
    return table;
}

class Parser {
public:
    Parser(const std::string& text, const std::string& input) : mText(text), mInput(input) {
        mProg.source = text;
    }

    ExprProgram run() {
        skipSpace();
        if (mPos >= mText.size()) fail(mPos, "the formula is empty");
        sum();
        skipSpace();
        if (mPos < mText.size()) fail(mPos, std::string("unexpected '") + mText[mPos] + "'");
        return std::move(mProg);
    }

private:
    [[noreturn]] void fail(std::size_t pos, const std::string& what) const {
        throw Error(mInput, what + " at column " + std::to_string(pos + 1) + "\n  " + mText + "\n  " +
                                std::string(pos, ' ') + "^");
    }

    void skipSpace() {
        while (mPos < mText.size() && std::isspace(static_cast<unsigned char>(mText[mPos]))) ++mPos;
    }
    bool accept(char c) {
        skipSpace();
        if (mPos < mText.size() && mText[mPos] == c) { ++mPos; return true; }
        return false;
    }
    void emit(ExprOp op, std::uint32_t arg, int stackDelta) {
        mProg.code.push_back({op, arg});
        mDepth += stackDelta;
        if (mDepth > mProg.maxStack) mProg.maxStack = mDepth;
        if (mDepth > kMaxStack) fail(mPos, "the formula is too long (more than " + std::to_string(kMaxStack) + " pending terms)");
    }

    void sum() {
        product();
        for (;;) {
            if (accept('+')) { product(); emit(ExprOp::Add, 0, -1); }
            else if (accept('-')) { product(); emit(ExprOp::Sub, 0, -1); }
            else return;
        }
    }
    void product() {
        unary();
        for (;;) {
            if (accept('*')) { unary(); emit(ExprOp::Mul, 0, -1); }
            else if (accept('/')) { unary(); emit(ExprOp::Div, 0, -1); }
            else return;
        }
    }
    void unary() {
        // Nesting depth bounds both this parser's recursion and the evaluators' fixed stacks.
        if (++mNesting > kMaxNesting) fail(mPos, "the formula nests deeper than " + std::to_string(kMaxNesting) + " levels");
        struct Leave { int& n; ~Leave() { --n; } } leave{mNesting};
        if (accept('-')) {
            unary();
            // A negative number is a constant (so that x^-2 is a power by a whole constant too).
            if (mProg.code.back().op == ExprOp::Const) mProg.constants[mProg.code.back().arg] *= -1;
            else emit(ExprOp::Neg, 0, 0);
            return;
        }
        if (accept('+')) { unary(); return; }
        power();
    }
    void power() {
        primary();
        if (accept('^')) { unary(); emitPow(); }
    }
    // x^2 is the commonest power in a formula (distances): by a small whole constant it is
    // multiplication, not std::pow (which took 40 % of meshing a CSG formula of 20 spikes).
    void emitPow() {
        if (!mProg.code.empty() && mProg.code.back().op == ExprOp::Const) {
            const double n = mProg.constants[mProg.code.back().arg];
            if (n == std::nearbyint(n) && std::fabs(n) <= kMaxIntegerPower) {
                mProg.code.pop_back();
                --mDepth;
                emit(ExprOp::PowInt, std::uint32_t(std::int32_t(n)), 0);
                return;
            }
        }
        emit(ExprOp::Pow, 0, -1);
    }
    void primary() {
        skipSpace();
        if (mPos >= mText.size()) fail(mPos, "the formula ends where a number, variable or '(' was expected");
        const char c = mText[mPos];
        if (std::isdigit(static_cast<unsigned char>(c)) || c == '.') { number(); return; }
        if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') { name(); return; }
        if (c == '(') {
            const std::size_t open = mPos++;
            sum();
            if (!accept(')')) fail(mPos < mText.size() ? mPos : open, "missing ')' for the '(' at column " + std::to_string(open + 1));
            return;
        }
        fail(mPos, std::string("unexpected '") + c + "'");
    }
    void number() {
        const std::size_t start = mPos;
        const char* begin = mText.c_str() + mPos;
        char* end = nullptr;
        const double v = std::strtod(begin, &end);
        if (end == begin) fail(start, "malformed number");
        mPos += std::size_t(end - begin);
        if (mPos < mText.size() && (std::isalpha(static_cast<unsigned char>(mText[mPos])) || mText[mPos] == '_'))
            fail(mPos, "a number runs into a name (write '2*x', not '2x')");
        pushConstant(v);
    }
    void pushConstant(double v) {
        mProg.constants.push_back(v);
        emit(ExprOp::Const, std::uint32_t(mProg.constants.size() - 1), +1);
    }
    void name() {
        const std::size_t start = mPos;
        while (mPos < mText.size() && (std::isalnum(static_cast<unsigned char>(mText[mPos])) || mText[mPos] == '_')) ++mPos;
        const std::string id = mText.substr(start, mPos - start);
        if (id == "x") { emit(ExprOp::X, 0, +1); return; }
        if (id == "y") { emit(ExprOp::Y, 0, +1); return; }
        if (id == "z") { emit(ExprOp::Z, 0, +1); return; }
        if (id == "pi") { pushConstant(3.14159265358979323846); return; }
        const auto fn = functions().find(id);
        if (fn == functions().end()) {
            fail(start, "unknown name '" + id + "' (variables: x, y, z, pi; functions: abs, min, max, sqrt, exp, log, "
                        "sin, cos, tan, pow, clamp)");
        }
        if (!accept('(')) fail(mPos, "'" + id + "' must be followed by '('");
        int args = 0;
        if (accept(')')) fail(mPos - 1, "'" + id + "' needs arguments");
        for (;;) {
            sum();
            ++args;
            if (accept(',')) continue;
            if (accept(')')) break;
            skipSpace();
            fail(mPos, mPos < mText.size() ? "expected ',' or ')' in the arguments of '" + id + "'"
                                          : "missing ')' after the arguments of '" + id + "'");
        }
        const FunctionSpec& spec = fn->second;
        if (args < spec.minArgs || (spec.maxArgs >= 0 && args > spec.maxArgs)) {
            std::string want = spec.maxArgs < 0 ? std::to_string(spec.minArgs) + " or more"
                               : spec.minArgs == spec.maxArgs ? std::to_string(spec.minArgs)
                                                              : std::to_string(spec.minArgs) + "-" + std::to_string(spec.maxArgs);
            fail(start, "'" + id + "' takes " + want + " argument" + (want == "1" ? "" : "s") + ", not " + std::to_string(args));
        }
        if (spec.op == ExprOp::Pow) emitPow();
        else emit(spec.op, std::uint32_t(args), 1 - args);
    }

    const std::string& mText;
    const std::string& mInput;
    std::size_t mPos = 0;
    int mDepth = 0;
    int mNesting = 0;
    static constexpr int kMaxNesting = 200;
    static constexpr double kMaxIntegerPower = 64;
    ExprProgram mProg;
};

} // namespace

namespace {

// ExprProgram::argumentEnd and foldAfter, from the steps' operand counts: each step's subtree
// starts where its first operand's does.
void indexArguments(ExprProgram& prog) {
    const std::size_t n = prog.code.size();
    prog.argumentEnd.assign(n, -1);
    prog.foldAfter.assign(n, ExprFold::None);
    std::vector<std::int32_t> starts; // of the subtrees on the stack
    for (std::size_t i = 0; i < n; ++i) {
        const ExprInstr& in = prog.code[i];
        std::size_t operands = 0;
        switch (in.op) {
        case ExprOp::Const: case ExprOp::X: case ExprOp::Y: case ExprOp::Z: operands = 0; break;
        case ExprOp::Add: case ExprOp::Sub: case ExprOp::Mul: case ExprOp::Div: case ExprOp::Pow: operands = 2; break;
        case ExprOp::Min: case ExprOp::Max: operands = in.arg; break;
        case ExprOp::Clamp: operands = 3; break;
        default: operands = 1; break;
        }
        if (operands > starts.size()) throw std::logic_error("expression: a step takes more operands than the stack holds");
        const std::size_t first = starts.size() - operands;
        if (in.op == ExprOp::Min || in.op == ExprOp::Max)
            for (std::size_t a = first + 1; a < starts.size(); ++a) {
                const std::int32_t end = a + 1 < starts.size() ? starts[a + 1] - 1 : std::int32_t(i) - 1;
                prog.argumentEnd[std::size_t(starts[a])] = end;
                prog.foldAfter[std::size_t(end)] = in.op == ExprOp::Min ? ExprFold::Min : ExprFold::Max;
                prog.skippableArguments = true;
            }
        const std::int32_t start = operands ? starts[first] : std::int32_t(i);
        starts.resize(first);
        starts.push_back(start);
    }
    if (starts.size() != 1) throw std::logic_error("expression: the program does not leave one value");
}

} // namespace

ExprProgram parseExpression(const std::string& text, const std::string& input) {
    static std::atomic<std::uint64_t> parses{0};
    ExprProgram prog = Parser(text, input).run();
    indexArguments(prog);
    prog.id = ++parses;
    return prog;
}

} // namespace vdbsurf
