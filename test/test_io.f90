!> Tests of the HDF5 model file (round trip, atomic write, bad files, the shell specification
!> and the 64-bit seed). The namelist configuration is tested in test_config.
module test_io
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_geometry_rotation, only: rotation_about_axis
   use anm_io_model, only: model_type, write_model, read_model
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_io

   character(len=*), parameter :: tmpdir = "build/test-tmp"

contains

   !> Tests of this suite.
   subroutine collect_io(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("model file round trip", test_model_round_trip), &
              new_unittest("model file errors name the file", test_model_errors)]
   end subroutine collect_io

   subroutine write_text(name, text)
      character(len=*), intent(in) :: name, text
      integer :: unit
      call execute_command_line("mkdir -p "//tmpdir)
      open (newunit=unit, file=tmpdir//"/"//name, status="replace", action="write")
      write (unit, '(a)') text
      close (unit)
   end subroutine write_text

   subroutine test_model_round_trip(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m, r
      logical :: tmp_left
      m%box = [10.0_wp, 11.0_wp, 12.0_wp]
      m%periodic = .false.
      allocate (m%shapes(2), m%shape_names(2))
      m%shapes(1) = sphere_shape(1.0_wp)
      m%shapes(2) = ellipsoid_shape(2.0_wp, 1.5_wp, 1.0_wp, 6)
      m%shape_names = [character(len=256) :: "sphere", "ellipsoid"]
      m%np = 3
      m%shape = [1, 2, 2]
      m%nmax = [0, 6, 4]
      m%sieve = [1, 1, 2]
      m%center = reshape([1.0_wp, 2.0_wp, 3.0_wp, 4.0_wp, 5.0_wp, 6.0_wp, 7.0_wp, 8.0_wp, 9.0_wp], [3, 3])
      allocate (m%rotation(3, 3, 3))
      m%rotation(:, :, 1) = rotation_about_axis([0.0_wp, 0.0_wp, 1.0_wp], 0.3_wp)
      m%rotation(:, :, 2) = rotation_about_axis([1.0_wp, 0.0_wp, 0.0_wp], 1.3_wp)
      m%rotation(:, :, 3) = rotation_about_axis([1.0_wp, 1.0_wp, 0.0_wp], 2.3_wp)
      m%scale = [1.0_wp, 2.0_wp, 0.5_wp]
      allocate (m%shell_thickness(1, 3))
      m%shell_thickness = 0.1_wp
      m%min_width = [4.0_wp, 1.0_wp]
      m%max_width = [5.0_wp, 2.0_wp]
      m%target_fraction = [0.2_wp, 0.1_wp]
      m%achieved_fraction = [0.19_wp, 0.1_wp]
      m%count = [2, 1]
      m%namelist = "&box length = 10, 11, 12 /"
      m%seed = 5000000000_i8
      m%layer_thickness = [0.01_wp]
      m%layer_colour = reshape([0.1_wp, 0.2_wp, 0.3_wp], [3, 1])
      m%layer_unit = "fraction"
      m%layer_mode = "overlap"
      m%version = "test"
      call execute_command_line("mkdir -p "//tmpdir)
      call write_model(tmpdir//"/round.h5", m, error)
      if (allocated(error)) return
      inquire (file=tmpdir//"/round.h5.tmp", exist=tmp_left)
      call check(error, .not. tmp_left, "temporary file left behind")
      if (allocated(error)) return
      call read_model(tmpdir//"/round.h5", r, error)
      if (allocated(error)) return
      call check(error, r%np == 3 .and. .not. r%periodic .and. all(r%box == m%box), "box and count")
      if (allocated(error)) return
      call check(error, all(r%shape == m%shape) .and. all(r%sieve == m%sieve) .and. all(r%nmax == m%nmax), "indices")
      if (allocated(error)) return
      call check(error, maxval(abs(r%rotation - m%rotation)) + maxval(abs(r%center - m%center)), 0.0_wp, "poses", &
                 thr=0.0_wp)
      if (allocated(error)) return
      call check(error, maxval(abs(r%shapes(2)%a - m%shapes(2)%a)), 0.0_wp, "coefficients", thr=1.0e-15_wp)
      if (allocated(error)) return
      call check(error, trim(r%shape_names(2)) == "ellipsoid" .and. r%namelist == m%namelist, "strings")
      if (allocated(error)) return
      call check(error, allocated(r%layer_unit), "/shells read back")
      if (allocated(error)) return
      call check(error, r%layer_unit == "fraction" .and. r%layer_mode == "overlap" .and. size(r%layer_thickness) == 1 &
                 .and. all(r%layer_colour == m%layer_colour) .and. all(r%layer_thickness == m%layer_thickness), &
                 "shell specification round trip")
   end subroutine test_model_round_trip

   subroutine test_model_errors(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: r
      type(error_type), allocatable :: err
      call read_model(tmpdir//"/absent.h5", r, err)
      call check(error, allocated(err), "missing file accepted")
      if (allocated(error)) return
      call check(error, index(err%message, "absent.h5") > 0, "names the file: "//err%message)
      if (allocated(error)) return
      call write_text("not-hdf5.h5", "plain text")
      call read_model(tmpdir//"/not-hdf5.h5", r, err)
      call check(error, allocated(err), "text file accepted as model")
      if (allocated(error)) return
      call check(error, index(err%message, "not-hdf5.h5") > 0, "names the file: "//err%message)
   end subroutine test_model_errors
end module test_io
