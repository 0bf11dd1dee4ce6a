!> Tests of the run configuration (src/config): valid input resolved to records and enumerators,
!> the resolved dump read back to the same configuration, and every kind of bad input refused
!> with a message naming the file, the line, the group and the variable.
module test_config
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_config_job, only: run_config_type, read_config, write_config, placement, contact_method, shell_mode, &
      & thickness_unit, vrml_layout
   use anm_config_parking, only: last_particle, sieve_carry
   use anm_shells_thickness, only: thickness_to_mm, thickness_to_shape_units
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_config

   character(len=*), parameter :: tmpdir = "build/test-tmp"
   character(len=*), parameter :: nl = new_line("a")

contains

   !> Tests of this suite.
   subroutine collect_config(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("valid namelist is resolved", test_valid), &
              new_unittest("choices resolve to enumerators", test_enumerators), &
              new_unittest("the resolved dump reads back to the same configuration", test_dump_round_trip), &
              new_unittest("share mode multiplies by the total fraction", test_share), &
              new_unittest("a 64-bit seed is kept", test_seed64), &
              new_unittest("unknown variable is named with its line", test_unknown_variable), &
              new_unittest("wrong type is refused with its line", test_wrong_type), &
              new_unittest("fractions above 1 are refused", test_fraction_sum), &
              new_unittest("a particle wider than the box is refused", test_too_wide), &
              new_unittest("negative width is refused with its line", test_negative_width), &
              new_unittest("missing group and file are refused", test_missing_group), &
              new_unittest("unknown group is refused with its line", test_unknown_group), &
              new_unittest("duplicate group is refused", test_duplicate_group), &
              new_unittest("NaN and Inf are refused", test_not_finite), &
              new_unittest("a binary file is not a namelist", test_binary), &
              new_unittest("text outside groups and unclosed groups are refused", test_structure), &
              new_unittest("thickness units convert in one place", test_thickness_units), &
              new_unittest("the thesis' sieve rules: resolved, dumped only when chosen, bad values named", &
                           test_sieve_rules)]
   end subroutine collect_config

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
      text = "&box length = 20, 20, 20, periodic = .true. /"//nl// &
             "&sieves nsieve = 2, min_width = 4.0, 1.0, max_width = 5.0, 2.0, fraction = 0.2, 0.1 /"//nl
   end function base_nml

   subroutine expect_error(error, name, text, fragment, fragment2)
      type(error_type), allocatable, intent(out) :: error
      character(len=*), intent(in) :: name, text, fragment
      character(len=*), intent(in), optional :: fragment2
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
      if (allocated(error)) return
      if (present(fragment2)) call check(error, index(err%message, fragment2) > 0, &
                                         "message must contain '"//fragment2//"': "//err%message)
   end subroutine expect_error

   subroutine test_valid(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: cfg
      call write_text("valid.nml", base_nml()//"&shells nlayer = 1, thickness = 0.02 /"//nl//"&run seed = 42 /")
      call read_config(tmpdir//"/valid.nml", cfg, error)
      if (allocated(error)) return
      call check(error, cfg%sieves%nsieve, 2, "nsieve")
      if (allocated(error)) return
      call check(error, cfg%sieves%target_fraction(2), 0.1_wp, "fraction")
      if (allocated(error)) return
      call check(error, cfg%run%seed == 42_i8 .and. cfg%shells%nlayer == 1 .and. cfg%shells%mode == shell_mode%exclude, &
                 "seed/shells")
      if (allocated(error)) return
      call check(error, cfg%parking%max_locations, 2000, "default max_locations")
      if (allocated(error)) return
      call check(error, cfg%output%tessellation(1), 32, "default tessellation")
      if (allocated(error)) return
      call check(error, index(write_config(cfg), "max_locations = 2000") > 0, "defaults written back")
   end subroutine test_valid

   subroutine test_enumerators(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: cfg
      call write_text("enums.nml", base_nml()//"&parking placement = 'VOID', contact_method = 'newton_raphson' /"//nl &
                      //"&shells nlayer = 2, thickness = 0.1, 0.2, thickness_unit = 'mm', mode = 'shell_overlap' /")
      call read_config(tmpdir//"/enums.nml", cfg, error)
      if (allocated(error)) return
      call check(error, cfg%parking%placement == placement%void, "placement%void")
      if (allocated(error)) return
      call check(error, cfg%parking%contact_method == contact_method%newton_raphson, "contact_method%newton_raphson")
      if (allocated(error)) return
      call check(error, cfg%shells%unit == thickness_unit%mm .and. cfg%shells%mode == shell_mode%shell_overlap, &
                 "thickness_unit%mm, shell_mode%shell_overlap")
      if (allocated(error)) return
      call write_text("enums-default.nml", base_nml())
      call read_config(tmpdir//"/enums-default.nml", cfg, error)
      if (allocated(error)) return
      call check(error, cfg%parking%placement == placement%uniform .and. cfg%parking%contact_method == contact_method%eob &
                 .and. cfg%shells%unit == thickness_unit%fraction_of_length .and. cfg%shells%nlayer == 0 &
                 .and. cfg%output%vrml_layout == vrml_layout%instanced, "defaults")
   end subroutine test_enumerators

   subroutine test_dump_round_trip(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: a, b
      call write_text("dump-in.nml", "&box length = 20, 21, 22, periodic = .false. /"//nl &
                      //"&sieves nsieve = 2, min_width = 4.0, 1.0, max_width = 5.0, 2.0, fraction = 0.5, 0.5," &
                      //" fraction_mode = 'share', total_fraction = 0.3, source = 'sphere', 'synthetic', order = 4, -1 /"//nl &
                      //"&synthetic count = 7, nmax = 12, rough_c = 0.1 /"//nl &
                      //"&parking max_locations = 99, placement = 'void', certified = .false. /"//nl &
                      //"&shells nlayer = 2, thickness = 0.01, 0.03, mode = 'overlap' /"//nl &
                      //"&output directory = 'out/x''y', name = 'm', vrml = .false., tessellation = 12," &
                      //" vrml_layout = 'Flat' /"//nl &
                      //"&run seed = 123456789012 /")
      call read_config(tmpdir//"/dump-in.nml", a, error)
      if (allocated(error)) return
      call write_text("dump-out.nml", write_config(a))
      call read_config(tmpdir//"/dump-out.nml", b, error)
      if (allocated(error)) return
      call check(error, write_config(a) == write_config(b), "dump of the dump differs")
      if (allocated(error)) return
      call check(error, all(a%box%length == b%box%length) .and. .not. b%box%periodic, "box")
      if (allocated(error)) return
      call check(error, all(a%sieves%target_fraction == b%sieves%target_fraction) .and. b%sieves%source(1) == "sphere" &
                 .and. all(b%sieves%order == [4, -1]), "sieves")
      if (allocated(error)) return
      call check(error, b%synthetic%count == 7 .and. b%synthetic%params%nmax == 12 .and. b%synthetic%params%rough_c == 0.1_wp, &
                 "synthetic")
      if (allocated(error)) return
      call check(error, b%parking%max_locations == 99 .and. b%parking%placement == placement%void &
                 .and. .not. b%parking%certified, "parking")
      if (allocated(error)) return
      call check(error, all(b%shells%thickness == [0.01_wp, 0.03_wp]) .and. b%shells%mode == shell_mode%overlap &
                 .and. all(b%shells%colour == a%shells%colour), "shells")
      if (allocated(error)) return
      call check(error, trim(b%output%directory) == "out/x'y" .and. .not. b%output%vrml &
                 .and. all(b%output%tessellation == a%output%tessellation) &
                 .and. b%output%vrml_layout == vrml_layout%flat, "output")
      if (allocated(error)) return
      call check(error, b%run%seed == 123456789012_i8, "seed")
   end subroutine test_dump_round_trip

   subroutine test_share(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: cfg
      call write_text("share.nml", "&box length = 66, 66, 66 /"//nl// &
                      "&sieves nsieve = 2, min_width = 10, 9, max_width = 11, 10, fraction = 0.5, 0.5, " &
                      //"fraction_mode = 'share', total_fraction = 0.25 /")
      call read_config(tmpdir//"/share.nml", cfg, error)
      if (allocated(error)) return
      call check(error, cfg%sieves%target_fraction(1), 0.125_wp, "share times total")
   end subroutine test_share

   subroutine test_seed64(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: cfg
      call write_text("seed64.nml", base_nml()//"&run seed = 9000000000000000001 /")
      call read_config(tmpdir//"/seed64.nml", cfg, error)
      if (allocated(error)) return
      call check(error, cfg%run%seed == 9000000000000000001_i8, "seed above 2^31 kept")
      if (allocated(error)) return
      call check(error, index(write_config(cfg), "seed = 9000000000000000001") > 0, "seed written back")
   end subroutine test_seed64

   subroutine test_unknown_variable(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "unknown.nml", base_nml()//"&parking max_locatoins = 5 /", "max_locatoins", "unknown.nml:3:")
   end subroutine test_unknown_variable

   subroutine test_wrong_type(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "type.nml", base_nml()//"&parking"//nl//"  n_ext = 40"//nl//"  max_locations = 'many' /", &
                        "&parking", "type.nml:5:")
   end subroutine test_wrong_type

   subroutine test_fraction_sum(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "sum.nml", "&box length = 20, 20, 20 /"//nl// &
                        "&sieves nsieve = 2, min_width = 4.0, 1.0, max_width = 5.0, 2.0, fraction = 0.7, 0.6 /", &
                        "fraction")
   end subroutine test_fraction_sum

   subroutine test_too_wide(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "wide.nml", "&box length = 20, 20, 4 /"//nl// &
                        "&sieves nsieve = 1, min_width = 4.0, max_width = 5.0, fraction = 0.2 /", "max_width(1)")
   end subroutine test_too_wide

   subroutine test_negative_width(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "negative.nml", "&box length = 20, 20, 20 /"//nl//"&sieves"//nl//" nsieve = 1"//nl &
                        //" max_width = 5.0, fraction = 0.2"//nl//" min_width = -1.0"//nl//"/", "min_width(1)", &
                        "negative.nml:5: &sieves")
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

   subroutine test_unknown_group(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "parkng.nml", base_nml()//"! comment"//nl//"&parkng max_locations = 5 /", &
                        "unknown namelist group &parkng", "parkng.nml:4:")
      if (allocated(error)) return
      call expect_error(error, "ouptut.nml", base_nml()//"&OUPTUT name = 'x' /", "&ouptut", "ouptut.nml:3:")
   end subroutine test_unknown_group

   subroutine test_duplicate_group(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "dup.nml", base_nml()//"&run seed = 1 /"//nl//"&run seed = 2 /", "given twice", &
                        "dup.nml:4:")
   end subroutine test_duplicate_group

   subroutine test_not_finite(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "nan.nml", "&box"//nl//" length = 20, NaN, 20 /"//nl &
                        //"&sieves nsieve = 1, min_width = 1, max_width = 2, fraction = 0.1 /", "length(2)", &
                        "nan.nml:2: &box")
      if (allocated(error)) return
      call expect_error(error, "inf.nml", base_nml()//"&shells nlayer = 1, thickness = Inf /", "not a finite number")
      if (allocated(error)) return
      call expect_error(error, "infw.nml", "&box length = 20, 20, 20 /"//nl &
                        //"&sieves nsieve = 1, min_width = 1, max_width = -Infinity, fraction = 0.1 /", "max_width(1)")
      if (allocated(error)) return
      call expect_error(error, "nanrough.nml", base_nml()//"&synthetic rough_beta = nan /", "rough_beta")
   end subroutine test_not_finite

   subroutine test_binary(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "model.h5", achar(137)//"HDF"//achar(13)//achar(10)//achar(26)//achar(10)//achar(0), &
                        "not a namelist file")
      if (allocated(error)) return
      call expect_error(error, "zeros.nml", "&box"//achar(0)//achar(1)//" /", "binary content")
      if (allocated(error)) return
      call expect_error(error, "empty.nml", "   ", "empty")
      if (allocated(error)) return
      call expect_error(error, "csv.nml", "a,b,c"//nl//"1,2,3", "outside a namelist group")
   end subroutine test_binary

   subroutine test_structure(error)
      type(error_type), allocatable, intent(out) :: error
      call expect_error(error, "open.nml", base_nml()//"&run seed = 1", "not closed", "open.nml:3:")
      if (allocated(error)) return
      call expect_error(error, "nested.nml", "&box length = 20, 20, 20"//nl//"&sieves nsieve = 1 /", "before &box")
      if (allocated(error)) return
      call expect_error(error, "stray.nml", base_nml()//"parking max_locations = 5 /", "stray.nml:3: text outside")
   end subroutine test_structure

   !> Thickness conversions against hand values: 0.02 of a length 3 at 0.5 mm/unit is 0.03 mm;
   !> 0.1 mm at 0.5 mm/unit is 0.2 shape units.
   subroutine test_thickness_units(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: tol = 1.0e-15_wp
      call check(error, thickness_to_mm(0.02_wp, thickness_unit%fraction_of_length, 3.0_wp, 0.5_wp), 0.03_wp, &
                 "fraction to mm", thr=tol)
      if (allocated(error)) return
      call check(error, thickness_to_mm(0.1_wp, thickness_unit%mm, 3.0_wp, 0.5_wp), 0.1_wp, "mm to mm", thr=tol)
      if (allocated(error)) return
      call check(error, thickness_to_shape_units(0.1_wp, thickness_unit%mm, 3.0_wp, 0.5_wp), 0.2_wp, "mm to shape", thr=tol)
      if (allocated(error)) return
      call check(error, thickness_to_shape_units(0.02_wp, thickness_unit%fraction_of_length, 3.0_wp, 0.5_wp), 0.06_wp, &
                 "fraction to shape", thr=tol)
   end subroutine test_thickness_units
   subroutine test_sieve_rules(error)
      type(error_type), allocatable, intent(out) :: error
      type(run_config_type) :: a, b
      ! defaults: today's rules, and the resolved text does not mention them (unchanged models)
      call write_text("rules-default.nml", base_nml())
      call read_config(tmpdir//"/rules-default.nml", a, error)
      if (allocated(error)) return
      call check(error, a%parking%last_particle == last_particle%closer .and. a%parking%sieve_carry == sieve_carry%rounding, &
                 "defaults are 'closer' and 'rounding'")
      if (allocated(error)) return
      call check(error, index(write_config(a), "last_particle") == 0 .and. index(write_config(a), "sieve_carry") == 0, &
                 "the default rules must not appear in the resolved text")
      if (allocated(error)) return
      ! the thesis' rules: resolved (any case) and written back
      call write_text("rules.nml", base_nml()//"&parking last_particle = 'Overshoot', sieve_carry = 'NONE' /")
      call read_config(tmpdir//"/rules.nml", a, error)
      if (allocated(error)) return
      call check(error, a%parking%last_particle == last_particle%overshoot .and. a%parking%sieve_carry == sieve_carry%none, &
                 "'overshoot' and 'none' resolved")
      if (allocated(error)) return
      call write_text("rules-out.nml", write_config(a))
      call read_config(tmpdir//"/rules-out.nml", b, error)
      if (allocated(error)) return
      call check(error, b%parking%last_particle == last_particle%overshoot .and. b%parking%sieve_carry == sieve_carry%none, &
                 "the rules did not survive the dump")
      if (allocated(error)) return
      call expect_error(error, "rules-bad1.nml", base_nml()//"&parking"//nl//"  last_particle = 'over' /", &
                        "last_particle", "rules-bad1.nml:4:")
      if (allocated(error)) return
      call expect_error(error, "rules-bad2.nml", base_nml()//"&parking"//nl//"  max_locations = 5"//nl &
                        //"  sieve_carry = 'all' /", "sieve_carry", "rules-bad2.nml:5:")
   end subroutine test_sieve_rules
end module test_config
