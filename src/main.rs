fn main() -> std::process::ExitCode {
    mesoflow::cli::main()
}
