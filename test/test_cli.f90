!> Tests of the command layer (anm_cli_arguments, anm_cli_commands): option values and the
!> messages of bad options, and commands run on argument lists as the program passes them
!> (docs/cli.md): the shape table of a sphere, unknown options, missing files.
module test_cli
   use anm_core_kinds, only: wp, pi
   use anm_core_error, only: error_type, error_code
   use anm_core_filesystem, only: string_type
   use anm_shapes_analytic, only: sphere_shape
   use anm_shapes_nist, only: write_nist_shape
   use anm_cli_arguments, only: int_option, real_option, wants_help
   use anm_cli_commands, only: shape_command, verify_command, write_command_usage, command_names
   use anm_cli_run, only: output_files, run_command
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_cli

contains

   !> Tests of this suite.
   subroutine collect_cli(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("int_option and real_option read values and advance", test_values), &
              new_unittest("bad option values are named with the offending text", test_bad_values), &
              new_unittest("anm shape: the table of a sphere file (exact volume)", test_shape_sphere), &
              new_unittest("anm shape: unknown option and missing path", test_shape_bad), &
              new_unittest("anm verify: a missing model file is named", test_verify_missing), &
              new_unittest("every command has a usage text; -h and --help are found", test_help), &
              new_unittest("usage errors carry error_code%usage, file errors do not", test_usage_class), &
              new_unittest("the outputs a run checks before overwriting", test_output_files)]
   end subroutine collect_cli

   !> An argument list from blank-separated words.
   function words(text) result(args)
      character(len=*), intent(in) :: text
      type(string_type), allocatable :: args(:)
      integer :: i, j
      allocate (args(0))
      i = 1
      do while (i <= len(text))
         if (text(i:i) == " ") then
            i = i + 1
            cycle
         end if
         j = index(text(i:), " ")
         if (j == 0) j = len(text) - i + 2
         args = [args, string_type(text(i:i + j - 2))]
         i = i + j
      end do
   end function words

   subroutine test_values(error)
      type(error_type), allocatable, intent(out) :: error
      type(string_type), allocatable :: args(:)
      integer :: i, n
      real(wp) :: x
      args = words("--order 12 --tolerance 1.5e-3")
      i = 1
      call int_option(args, i, "--order", n, error, minimum=0)
      if (allocated(error)) return
      call check(error, n, 12, "--order")
      if (allocated(error)) return
      call check(error, i, 2, "position after --order")
      if (allocated(error)) return
      i = 3
      call real_option(args, i, "--tolerance", x, error)
      if (allocated(error)) return
      call check(error, x, 1.5e-3_wp, "--tolerance", thr=0.0_wp)
   end subroutine test_values

   subroutine test_bad_values(error)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: got
      type(string_type), allocatable :: args(:)
      integer :: i, n
      real(wp) :: x
      args = words("--order x1 --order -1 --tolerance 1mm --seed")
      i = 1
      call int_option(args, i, "--order", n, got)
      call expect(error, got, "option --order: 'x1' is not an integer")
      if (allocated(error)) return
      i = 3
      call int_option(args, i, "--order", n, got, minimum=0)
      call expect(error, got, "option --order: -1 must be >= 0")
      if (allocated(error)) return
      i = 5
      call real_option(args, i, "--tolerance", x, got)
      call expect(error, got, "option --tolerance: '1mm' is not a number")
      if (allocated(error)) return
      i = 7
      call int_option(args, i, "--seed", n, got)
      call expect(error, got, "option --seed needs a value")
   end subroutine test_bad_values

   !> Fail unless `got` is an error whose message contains `text`.
   subroutine test_help(error)
      type(error_type), allocatable, intent(out) :: error
      integer :: k, unit
      logical :: found
      character(len=256) :: line
      open (newunit=unit, status="scratch", action="readwrite")
      do k = 1, size(command_names)
         call write_command_usage(unit, trim(command_names(k)), found)
         call check(error, found, "no usage text for "//trim(command_names(k)))
         if (allocated(error)) return
      end do
      call write_command_usage(unit, "frobnicate", found)
      call check(error, .not. found, "usage text for an unknown command")
      if (allocated(error)) return
      rewind (unit)
      read (unit, '(a)') line
      close (unit)
      call check(error, index(line, "run FILE.nml") > 0, "first usage line: "//trim(line))
      if (allocated(error)) return
      call check(error, wants_help(words("a.h5 --help")) .and. wants_help(words("-h")) &
                 .and. .not. wants_help(words("a.h5 --force")), "wants_help")
   end subroutine test_help

   subroutine test_usage_class(error)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: got
      integer :: status
      call verify_command(words("m.h5 --bogus"), 6, status, got)
      call check(error, got%stat, error_code%usage, "unknown option")
      if (allocated(error)) return
      deallocate (got)
      call verify_command(words("m.h5 --resolution x"), 6, status, got)
      call check(error, got%stat, error_code%usage, "bad option value")
      if (allocated(error)) return
      deallocate (got)
      call run_command(words("a.nml b.nml"), 6, 0, got)
      call check(error, got%stat, error_code%usage, "two namelists")
      if (allocated(error)) return
      deallocate (got)
      call verify_command(words("build/test-tmp/no-such-model.h5"), 6, status, got)
      call check(error, got%stat /= error_code%usage, "a missing file is not a usage error")
   end subroutine test_usage_class

   subroutine test_output_files(error)
      type(error_type), allocatable, intent(out) :: error
      type(string_type), allocatable :: f(:)
      f = output_files("o/m", .true., .false., 2)
      call check(error, size(f), 3, "model, summary, VRML")
      if (allocated(error)) return
      call check(error, f(1)%s == "o/m.h5" .and. f(2)%s == "o/m-summary.csv" .and. f(3)%s == "o/m.wrl", "names")
      if (allocated(error)) return
      f = output_files("o/m", .true., .true., 2)
      call check(error, size(f), 5, "per layer")
      if (allocated(error)) return
      call check(error, f(3)%s == "o/m-particles.wrl" .and. f(5)%s == "o/m-layer2.wrl", "per-layer names")
      if (allocated(error)) return
      f = output_files("o/m", .false., .false., 0)
      call check(error, size(f), 2, "without VRML")
   end subroutine test_output_files

   subroutine expect(error, got, text)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable, intent(in) :: got
      character(len=*), intent(in) :: text
      if (.not. allocated(got)) then
         call check(error, .false., "no error, expected '"//text//"'")
      else
         call check(error, index(got%message, text) > 0, "message '"//got%message//"', expected '"//text//"'")
      end if
   end subroutine expect

   subroutine test_shape_sphere(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=*), parameter :: dir = "build/test-tmp", file = dir//"/cli-sphere.dat", table = dir//"/cli-shape.txt"
      character(len=512) :: header, row
      character(len=64) :: name
      real(wp) :: ext(6), volume
      integer :: unit, stat
      call execute_command_line("mkdir -p "//dir)
      call write_nist_shape(file, sphere_shape(2.0_wp), error)
      if (allocated(error)) return
      open (newunit=unit, file=table, status="replace", action="readwrite")
      call shape_command(words(file//" --order 0"), unit, error)
      if (allocated(error)) return
      rewind (unit)
      read (unit, '(a)') header
      read (unit, '(a)') row
      close (unit, status="delete")
      call check(error, header(1:5) == "Name ", "header: "//trim(header))
      if (allocated(error)) return
      read (row, *, iostat=stat) name, ext, volume
      call check(error, stat == 0 .and. trim(name) == "cli-sphere.dat", "row: "//trim(row))
      if (allocated(error)) return
      call check(error, volume, 32.0_wp / 3.0_wp * pi, "volume of the sphere of radius 2", rel=1.0e-5_wp)
      if (allocated(error)) return
      call check(error, ext(2), 2.0_wp, "xhi", rel=1.0e-5_wp)
   end subroutine test_shape_sphere

   subroutine test_shape_bad(error)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: got
      call shape_command(words("some.dat --bogus"), 6, got)
      call expect(error, got, "anm shape: unknown option '--bogus'")
      if (allocated(error)) return
      call shape_command(words("--order 3"), 6, got)
      call expect(error, got, "anm shape: missing FILE or DIR argument")
      if (allocated(error)) return
      call shape_command(words("build/test-tmp/no-such-shape.dat"), 6, got)
      call expect(error, got, "no-such-shape.dat")
   end subroutine test_shape_bad

   subroutine test_verify_missing(error)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: got
      integer :: status
      call verify_command(words("build/test-tmp/no-such-model.h5"), 6, status, got)
      call expect(error, got, "no-such-model.h5")
   end subroutine test_verify_missing
end module test_cli
