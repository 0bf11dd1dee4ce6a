!> Tests of the namelist configuration (valid input and every kind of bad input, each a named
!> error) and of the HDF5 model file (round trip, atomic write, bad files).
module test_io
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_geometry_rotation, only: rotation_about_axis
   use anm_parking_config, only: run_config_type, read_config, resolved_namelist, shell_mode
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
              new_unittest("valid namelist is resolved", test_valid), &
              new_unittest("share mode multiplies by the total fraction", test_share), &
              new_unittest("unknown variable is named", test_unknown_variable), &
              new_unittest("wrong type is refused", test_wrong_type), &
              new_unittest("fractions above 1 are refused", test_fraction_sum), &
              new_unittest("a particle wider than the box is refused", test_too_wide), &
              new_unittest("negative width is refused", test_negative_width), &
              new_unittest("missing group and file are refused", test_missing_group), &
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

   function base_nml() result(text)
      character(len=:), allocatable :: text
      text = "&box length = 20, 20, 20, periodic = .true. /"//new_line("a")// &
             "&sieves nsieve = 2, min_width = 4.0, 1.0, max_width = 5.0, 2.0, fraction = 0.2, 0.1 /"//new_line("a")
   end function base_nml

   subroutine expect_error(error, name, text, fragment)
      type(error_type), allocatable, intent(out) :: error
      character(len=*), intent(in) :: name, text, fragment
      type(run_config_type) :: cfg
      type(error_type), allocatable :: err
      call write_text(name, text)
      call read_config(tmpdir//"/"//name, cfg, err)
      call check(error, allocated(err), "no error for "//name)
      if (allocated(error)) return
      print '(a)', "        refused as expected: "//err%message
      call check(error, index(err%message, tmpdir//"/"//name) > 0, "message must name the file: "//err%message)
      if (allocated(error)) return
      call check(error, index(err%message, fragment) > 0, "message must contain '"//fragment//"': "//err%message)
   end subroutine expect_error

   subroutine test_valid(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: cfg
      call write_text("valid.nml", base_nml()//"&shells nlayer = 1, thickness = 0.02 /"//new_line("a") &
                      //"&run seed = 42 /")
      call read_config(tmpdir//"/valid.nml", cfg, error)
      if (allocated(error)) return
      call check(error, cfg%nsieve, 2, "nsieve")
      if (allocated(error)) return
      call check(error, cfg%target_fraction(2), 0.1_wp, "fraction")
      if (allocated(error)) return
      call check(error, cfg%seed == 42_i8 .and. cfg%nlayer == 1 .and. cfg%mode == shell_mode%exclude, "seed/shells")
      if (allocated(error)) return
      call check(error, cfg%max_locations, 2000, "default max_locations")
      if (allocated(error)) return
      call check(error, index(resolved_namelist(cfg), "max_locations = 2000") > 0, "defaults written back")
   end subroutine test_valid

   subroutine test_share(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: cfg
      call write_text("share.nml", "&box length = 66, 66, 66 /"//new_line("a")// &
                      "&sieves nsieve = 2, min_width = 10, 9, max_width = 11, 10, fraction = 0.5, 0.5, " &
                      //"fraction_mode = 'share', total_fraction = 0.25 /")
      call read_config(tmpdir//"/share.nml", cfg, error)
      if (allocated(error)) return
      call check(error, cfg%target_fraction(1), 0.125_wp, "share times total")
   end subroutine test_share

   subroutine test_unknown_variable(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "unknown.nml", base_nml()//"&parking max_locatoins = 5 /", "max_locatoins")
   end subroutine test_unknown_variable

   subroutine test_wrong_type(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "type.nml", base_nml()//"&parking max_locations = 'many' /", "&parking")
   end subroutine test_wrong_type

   subroutine test_fraction_sum(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "sum.nml", "&box length = 20, 20, 20 /"//new_line("a")// &
                        "&sieves nsieve = 2, min_width = 4.0, 1.0, max_width = 5.0, 2.0, fraction = 0.7, 0.6 /", &
                        "fraction")
   end subroutine test_fraction_sum

   subroutine test_too_wide(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "wide.nml", "&box length = 20, 20, 4 /"//new_line("a")// &
                        "&sieves nsieve = 1, min_width = 4.0, max_width = 5.0, fraction = 0.2 /", "max_width(1)")
   end subroutine test_too_wide

   subroutine test_negative_width(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "negative.nml", "&box length = 20, 20, 20 /"//new_line("a")// &
                        "&sieves nsieve = 1, min_width = -1.0, max_width = 5.0, fraction = 0.2 /", "min_width(1)")
   end subroutine test_negative_width

   subroutine test_missing_group(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: cfg
      type(error_type), allocatable :: err
      call expect_error(error, "nosieves.nml", "&box length = 20, 20, 20 /", "&sieves")
      if (allocated(error)) return
      call read_config(tmpdir//"/does-not-exist.nml", cfg, err)
      call check(error, allocated(err), "missing file accepted")
      if (allocated(error)) return
      call check(error, index(err%message, "does-not-exist.nml") > 0, "names the file")
   end subroutine test_missing_group

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
