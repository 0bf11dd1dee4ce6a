!> Benchmark of shell construction (one thread): time per shell on the 120 x 240 Gauss grid for
!> real particles (MA111-7-coarse, truncated at degree 14) and thicknesses of 0.1 %, 2 % and 10 %
!> of the particle length, with the Newton/fallback counts, the fitted order and residual, and a
!> per-phase breakdown: the surface precomputation (`new_shell_surface`) and R_t on the grid
!> (`offset_grid`) timed on their own (CPU ms, best of 3); the rest of a shell is the fit.
!> Run: bash scripts/bench.sh (figures: docs/performance.md; analysis: docs/performance-notes.md).
!> Argument: the shapes folder (default ../shared/shapes/MA111-7-coarse).
program bench_shells
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_shapes_library, only: shape_set_type, load_shapes
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_shells_build, only: shell_report_type, build_shell, build_layers, default_shell_ntheta, default_order_cap
   use anm_shells_surface, only: shell_surface_type, new_shell_surface
   use anm_shells_offset, only: offset_grid, offset_counts_type
   implicit none
   integer, parameter :: degree = 14, nshape = 4, nrep = 3
   real(wp), parameter :: fractions(3) = [0.001_wp, 0.02_wp, 0.10_wp]
   type(shape_set_type) :: set
   type(error_type), allocatable :: error
   type(sh_expansion_type) :: s, outer
   type(shape_geometry_type) :: geom
   type(shell_report_type) :: rep
   type(sh_expansion_type), allocatable :: layers(:)
   type(shell_report_type), allocatable :: reps(:)
   type(shell_surface_type) :: surf
   type(offset_counts_type) :: counts
   real(wp), allocatable :: rt(:, :)
   character(len=512) :: folder
   real(wp) :: t0, c0, c1, best, best_cpu, best_surf, best_offset
   integer :: k, f, r, nt

   folder = "../shared/shapes/MA111-7-coarse"
   if (command_argument_count() >= 1) call get_command_argument(1, folder)
   call load_shapes(trim(folder), set, error)
   if (allocated(error)) then
      write (error_unit, '(a)') error%message
      error stop 1
   end if
   write (output_unit, '(a)') "# shell construction, 1 thread, degree 14, 120 x 240 grid; best of 3 (wall clock and CPU time)"
   write (output_unit, '(a)') "# shape                          t/L  wall ms   cpu ms  newton continued fallback  evals order"// &
      " lifts   inside/t  outside/t  surf ms   R_t ms"
   nt = default_shell_ntheta
   allocate (rt(nt, 2 * nt))
   do k = 1, min(nshape, size(set%shapes))
      s = sh_truncate(set%shapes(k), degree)
      call compute_geometry(s, geom)
      do f = 1, size(fractions)
         best = huge(1.0_wp)
         best_cpu = huge(1.0_wp)
         do r = 1, nrep
            t0 = wall()
            call cpu_time(c0)
            call build_shell(s, fractions(f) * geom%length, outer, rep, error, label=set%names(k)%s)
            call cpu_time(c1)
            best = min(best, wall() - t0)
            best_cpu = min(best_cpu, c1 - c0)
            if (allocated(error)) then
               write (error_unit, '(a)') error%message
               error stop 1
            end if
         end do
         ! the phases on their own: surface precomputation, then R_t on its grid
         best_surf = huge(1.0_wp)
         best_offset = huge(1.0_wp)
         do r = 1, nrep
            call cpu_time(c0)
            call new_shell_surface(surf, s, nt, default_order_cap(s%nmax, nt))
            call cpu_time(c1)
            best_surf = min(best_surf, c1 - c0)
            call cpu_time(c0)
            call offset_grid(surf, fractions(f) * geom%length, rt, counts)
            call cpu_time(c1)
            best_offset = min(best_offset, c1 - c0)
         end do
         write (output_unit, '(a30,f7.3,2f9.2,i8,i10,i9,i7,i6,i6,2es11.3,2f9.2)') set%names(k)%s, fractions(f), &
            1.0e3_wp * best, 1.0e3_wp * best_cpu, &
            rep%newton, rep%continued, rep%fallback, rep%evaluations, rep%order, rep%lifts, rep%fit_inside / rep%thickness, &
            rep%fit_outside / rep%thickness, 1.0e3_wp * best_surf, 1.0e3_wp * best_offset
      end do
      ! the three thicknesses as layers (one surface precomputation, as the parking engine does)
      best = huge(1.0_wp)
      best_cpu = huge(1.0_wp)
      do r = 1, nrep
         t0 = wall()
         call cpu_time(c0)
         call build_layers(s, fractions * geom%length, layers, reps, error, label=set%names(k)%s)
         call cpu_time(c1)
         best = min(best, wall() - t0)
         best_cpu = min(best_cpu, c1 - c0)
         if (allocated(error)) then
            write (error_unit, '(a)') error%message
            error stop 1
         end if
      end do
      write (output_unit, '(a30,a7,2f9.2,a)') set%names(k)%s, " layers", 1.0e3_wp * best, 1.0e3_wp * best_cpu, &
         "   (build_layers, all three thicknesses)"
   end do

contains

   !> Wall-clock seconds.
   function wall() result(sec)
      real(wp) :: sec
      integer(i8) :: c, rate
      call system_clock(c, rate)
      sec = real(c, wp) / real(rate, wp)
   end function wall
end program bench_shells
