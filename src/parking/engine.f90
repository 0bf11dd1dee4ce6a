!> The parking driver (thesis section 2.1, Fig 1.3): reads the configuration, loads the shapes,
!> describes the particle kinds, runs the placement strategy on a packing and fills the model.
!>
!> The pieces: anm_parking_kinds (particle kinds, built lazily), anm_parking_packing (the parked
!> particles, their cell list and the overlap test of a candidate pose), anm_parking_attempts (the
!> per-particle random streams and the thesis' nested attempt order), anm_parking_scheduler (the
!> parallel batches) and the strategies: anm_parking_rsa (random sequential addition, sieve by
!> sieve) and anm_parking_dense (RSA with relaxation sweeps of hard-particle moves). Only this driver reads `run_config_type`; the pieces take their own parameter records,
!> filled here.
!>
!> Adding a strategy: add an enumerator to `parking_strategy`, a module that parks into the
!> packing (as anm_parking_rsa does) and a case in `run_parking`.
!>
!> Usage:
!>     call run_parking(cfg, model, kinds, kind_of, error, progress_unit=error_unit)
module anm_parking_engine
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_shapes_library, only: shape_set_type
   use anm_shapes_source, only: load_shape_source
   use anm_config_job, only: run_config_type, placement, write_config
   use anm_config_parking, only: parking_strategy, last_particle, sieve_carry
   use anm_shells_thickness, only: thickness_to_mm, thickness_unit
   use anm_parking_kinds, only: particle_kind_type, kind_params_type, kind_set_type, new_kind_set, width_levels, &
      & cache_environment, kind_bytes, body_bytes, body_holder
   use anm_parking_packing, only: packing_type, packing_params_type, new_packing
   use anm_parking_attempts, only: attempt_params_type
   use anm_parking_rsa, only: park_rsa, rsa_params_type, sieve_result_type, run_state_type
   use anm_parking_scheduler, only: phase1_distributor_type
   use anm_parking_dense, only: park_dense, dense_params_type
   use anm_io_model, only: model_type
   use anm_io_hdf5, only: block_start
   use omp_lib, only: omp_get_max_threads
   implicit none
   private

   public :: run_parking, particle_kind_type, width_levels, parking_strategy, body_holder, particle_share

contains

   !> Build the model the configuration asks for. Progress goes to `progress_unit` (stderr in the
   !> program) about every two seconds.
   subroutine run_parking(cfg, model, kinds, kind_of, error, progress_unit, max_batch, dist)
      !> Validated configuration.
      type(run_config_type), intent(in) :: cfg
      !> The packed model.
      type(model_type), intent(out) :: model
      !> Precomputed kinds (also used for VRML output).
      type(particle_kind_type), allocatable, intent(out) :: kinds(:)
      !> Kind of each particle.
      integer, allocatable, intent(out) :: kind_of(:)
      !> Error: a shape source cannot be read, a shell cannot be built.
      type(error_type), allocatable, intent(out) :: error
      !> Unit for progress lines (none when absent).
      integer, intent(in), optional :: progress_unit
      !> Largest batch of speculated particles (default: no limit; 1 runs the plain serial
      !> algorithm, which tests use as the reference).
      integer, intent(in), optional :: max_batch
      !> Phase 1 spread over processes (the MPI build); batches sized for all their threads.
      class(phase1_distributor_type), intent(in), optional :: dist
      type(kind_set_type) :: ks
      type(packing_type) :: pk
      type(packing_params_type) :: pp
      type(attempt_params_type), allocatable :: ap(:)
      type(rsa_params_type) :: rp
      type(sieve_result_type), allocatable :: result(:)
      type(run_state_type) :: run
      integer, allocatable :: first_shape(:), nshape(:)
      integer :: s
      integer(i8) :: t1

      call load_sources(cfg, model, first_shape, nshape, error)
      if (allocated(error)) return
      call new_kind_set(ks, kinds, kind_params(cfg), model%shapes, model%shape_names, first_shape, nshape, &
                        cfg%sieves%order(:cfg%sieves%nsieve))
      rp = rsa_params(cfg, progress_unit, max_batch)
      pp = packing_params(cfg)
      if (present(dist)) then
         allocate (rp%dist, source=dist)
         rp%nthreads = dist%workers
         ! the spatial decomposition parks by RSA; the dense strategy's sweeps move particles
         ! anywhere, so it runs with replicated data (docs/mpi.md)
         if (cfg%parking%strategy == parking_strategy%dense) rp%dist%spatial = .false.
         if (rp%dist%spatial) then
            pp%nslab = rp%dist%nslab
            pp%slab = rp%dist%slab
            pp%divided = divides_arrays(cfg, pp%nslab)
         end if
         ! the processes build the kinds in shares and exchange them; the on-disk cache is then
         ! not used (its hits could differ between the processes, which must build the same lists
         ! together)
         call dist%kinds_exchange(ks%exchange)
         if (allocated(ks%exchange)) then
            if (ks%exchange%nranks > 1) ks%cache%on = .false.
         end if
      end if
      call new_packing(pk, pp, kinds)
      allocate (ap(cfg%sieves%nsieve))
      do s = 1, cfg%sieves%nsieve
         ap(s) = attempt_params(cfg, ks, s)
      end do
      ! particles speculated per batch: any value gives the same model (anm_parking_scheduler),
      ! so the batch adapts to the machine and to the sieve (next_batch)
      run%batch = min(rp%nthreads, rp%batch_limit)
      call system_clock(run%t0, run%rate)
      run%tlast = run%t0
      run%vol_total = sum(cfg%sieves%target_fraction(:cfg%sieves%nsieve)) * product(cfg%box%length)

      select case (cfg%parking%strategy)
      case (parking_strategy%dense)
         call park_dense(pk, ks, ap, rp, dense_params(cfg), cfg%sieves%target_fraction(:cfg%sieves%nsieve), result, &
                         run, error)
      case default
         call park_rsa(pk, ks, ap, rp, cfg%sieves%target_fraction(:cfg%sieves%nsieve), result, run, error)
      end select
      if (allocated(error)) return
      ! divided arrays: the particles to their blocks of global ids (the output's), process r
      ! holding ids N r / n + 1 .. N (r + 1) / n
      if (pk%p%divided) call rp%dist%to_blocks(pk)
      ! the shell layers of the kinds that hold particles (the VRML output draws every kind), and
      ! the shell fractions they give
      if (cfg%shells%nlayer > 0) then
         if (cfg%output%vrml) then
            call ks%build_layers(pk%kinds, [(s, s=1, size(pk%kinds))], error)
         else
            call ks%build_layers(pk%kinds, kinds_in_use(pk, rp), error)
         end if
         if (allocated(error)) return
         call add_shell_fractions(pk, rp, result)
      else if (cfg%output%vrml) then
         call ks%build(pk%kinds, [(s, s=1, size(pk%kinds))], error)
         if (allocated(error)) return
      end if
      call system_clock(t1)
      call cache_line(ks, pk%kinds, progress_unit)
      model%attempts = run%attempts
      model%wall_time = real(t1 - run%t0, wp) / run%rate
      call fill_model(cfg, pk, result, model)
      if (pk%p%divided) model%first = int(block_start(int(pk%ntotal, i8), rp%dist%rank, rp%dist%nranks))
      call take_int1(pk%kind_of, pk%np, kind_of)
      call move_alloc(pk%kinds, kinds)
   end subroutine run_parking

   !> Whether slabs divide the particle arrays: each process then holds only its slab's
   !> particles and halo, unless void placement (its grid is fed every particle on every process)
   !> or the VRML file (written by one process from every particle) needs them all, or the dense
   !> strategy runs (replicated; docs/mpi.md).
   pure logical function divides_arrays(cfg, nslab) result(yes)
      !> Validated configuration.
      type(run_config_type), intent(in) :: cfg
      !> Slabs.
      integer, intent(in) :: nslab
      yes = nslab > 1 .and. cfg%parking%placement /= placement%void .and. .not. cfg%output%vrml .and. &
            cfg%parking%strategy /= parking_strategy%dense
   end function divides_arrays

   !> Estimate of the share of a run's particles that one process holds with `nslab` slabs (1
   !> unless they divide the arrays): its slab plus a halo of three of the largest widths on each
   !> face (the halo is the largest bounding radius plus each particle's own: a grain three times
   !> as long as its sieve width reaches that far).
   pure real(wp) function particle_share(cfg, nslab) result(share)
      !> Validated configuration.
      type(run_config_type), intent(in) :: cfg
      !> Slabs (processes).
      integer, intent(in) :: nslab
      share = 1.0_wp
      if (.not. divides_arrays(cfg, nslab)) return
      share = min(1.0_wp, 1.0_wp / nslab + 6.0_wp * maxval(cfg%sieves%max_width(:cfg%sieves%nsieve)) &
                                            / cfg%box%length(1))
   end function particle_share

   !> The kinds of the parked particles, each once, in increasing order (divided arrays: of the
   !> particles of every process; collective).
   function kinds_in_use(pk, rp) result(list)
      type(packing_type), intent(in) :: pk
      type(rsa_params_type), intent(in) :: rp
      integer, allocatable :: list(:)
      logical, allocatable :: used(:)
      integer :: i, k
      allocate (used(size(pk%kinds)))
      used = .false.
      do i = 1, pk%np
         used(pk%kind_of(i)) = .true.
      end do
      if (pk%p%divided) call rp%dist%any_over_ranks(used)
      list = pack([(k, k=1, size(pk%kinds))], used)
   end function kinds_in_use

   !> The shell volume fraction of each sieve (the sum of its particles' shell volumes over the
   !> box volume, not corrected for overlaps), from the built layers, particle by particle in
   !> the order they were parked (divided arrays: each process holds a block of them in that
   !> order and continues the sums of the blocks before it; collective).
   subroutine add_shell_fractions(pk, rp, result)
      type(packing_type), intent(in) :: pk
      type(rsa_params_type), intent(in) :: rp
      type(sieve_result_type), intent(inout) :: result(:)
      integer :: i, k, s
      real(wp) :: sc
      real(wp) :: sums(size(result))
      result%shell_fraction = 0.0_wp
      if (pk%p%divided) then
         sums = 0.0_wp
         call rp%dist%running_start(sums)
         result%shell_fraction = sums
      end if
      do i = 1, pk%np
         k = pk%kind_of(i)
         s = pk%sieve(i)
         sc = pk%scale(i)
         result(s)%shell_fraction = result(s)%shell_fraction &
                                    + sc**3 * (pk%kinds(k)%layer_volume(rp%nlayer) - pk%kinds(k)%volume) / rp%vbox
      end do
      if (pk%p%divided) then
         sums = result%shell_fraction
         call rp%dist%running_end(sums)
         result%shell_fraction = sums
      end if
   end subroutine add_shell_fractions

   !> Load the shapes of every sieve (each distinct source once) into the model: sieve s uses
   !> shapes first_shape(s) + 1 .. first_shape(s) + nshape(s).
   subroutine load_sources(cfg, model, first_shape, nshape, error)
      type(run_config_type), intent(in) :: cfg
      type(model_type), intent(inout) :: model
      integer, allocatable, intent(out) :: first_shape(:), nshape(:)
      type(error_type), allocatable, intent(out) :: error
      type(shape_set_type), allocatable :: sets(:)
      integer, allocatable :: set_of(:), set_first(:)
      character(len=512), allocatable :: src(:)
      integer :: s, nset, k, i, total

      allocate (set_of(cfg%sieves%nsieve), src(cfg%sieves%nsieve))
      nset = 0
      do s = 1, cfg%sieves%nsieve
         set_of(s) = 0
         do i = 1, nset
            if (src(i) == cfg%sieves%source(s)) set_of(s) = i
         end do
         if (set_of(s) == 0) then
            nset = nset + 1
            src(nset) = cfg%sieves%source(s)
            set_of(s) = nset
         end if
      end do
      allocate (sets(nset), set_first(nset))
      total = 0
      do i = 1, nset
         call load_shape_source(src(i), cfg%synthetic%params, cfg%run%seed, cfg%synthetic%count, sets(i), error)
         if (allocated(error)) then
            error%message = cfg%file//": &sieves: source = '"//trim(src(i))//"': "//error%message
            return
         end if
         set_first(i) = total
         total = total + size(sets(i)%shapes)
      end do
      allocate (model%shapes(total), model%shape_names(total))
      do i = 1, nset
         do k = 1, size(sets(i)%shapes)
            model%shapes(set_first(i) + k) = sets(i)%shapes(k)
            model%shape_names(set_first(i) + k) = sets(i)%names(k)%s
         end do
      end do
      allocate (first_shape(cfg%sieves%nsieve), nshape(cfg%sieves%nsieve))
      do s = 1, cfg%sieves%nsieve
         first_shape(s) = set_first(set_of(s))
         nshape(s) = size(sets(set_of(s))%shapes)
      end do
   end subroutine load_sources

   !> Lines about the kinds built (with shells: their number and memory), the contact bodies given
   !> support tables and the on-disk cache (when it is on or could not be used).
   subroutine cache_line(ks, kinds, unit)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(in) :: kinds(:)
      integer, intent(in), optional :: unit
      integer(i8) :: total, bare
      integer :: k, n, nb
      if (.not. present(unit)) return
      if (unit < 0) return
      if (ks%p%nlayer > 0) then
         total = 0
         bare = 0
         n = count(ks%built)
         nb = 0
         do k = 1, size(kinds)
            if (.not. ks%built(k)) cycle
            total = total + kind_bytes(kinds(k))
            if (kinds(k)%body_kind /= k) cycle
            nb = nb + 1
            bare = bare + body_bytes(kinds(k)%body)
         end do
         ! the bare bodies are shared by the width levels (and sieves) of their (shape, order)
         write (unit, '(a,i0,a,i0,a,i0,a,i0,a,f0.2,a,f0.1,a)') "kinds: ", n, " of ", size(kinds), " built, ", &
            nint(real(total - bare, wp) / max(1, n) / 2.0_wp**10), " kB per kind beside ", nb, &
            " shared contact bodies of ", real(bare, wp) / max(1, nb) / 2.0_wp**20, " MB, ", &
            real(total, wp) / 2.0_wp**20, " MB in all"
      end if
      write (unit, '(a,i0,a)') "kinds: support tables built for ", ks%tables_built, " contact bodies"
      if (allocated(ks%exchange)) then
         if (ks%exchange%nranks > 1) write (unit, '(a,i0,a,i0,a,i0,a)') "kinds: built in shares by ", &
            ks%exchange%nranks, " processes: ", ks%exchange%built, " parts (bodies, shells) built by this one, ", &
            ks%exchange%received, " received from the others (the kind cache is not used)"
      end if
      if (ks%cache%on) then
         write (unit, '(a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a)') "kinds: ", ks%bases_built, " bases and ", ks%shells_built, &
            " shells built; cache "//ks%cache%dir//": ", ks%cache%hits, " read, ", ks%cache%written, " written, ", &
            ks%cache%rejected, " rejected, ", ks%cache%misses, " missing, ", ks%cache%write_failed, " not written"
         if (ks%cache%write_failed > 0) write (unit, '(a)') "warning: kind cache: "//ks%cache%problem
      else if (allocated(ks%cache%problem)) then
         if (len(ks%cache%problem) > 0) write (unit, '(a)') "warning: kind cache not used: "//ks%cache%problem
      end if
   end subroutine cache_line

   !> What building kinds needs of the configuration.
   function kind_params(cfg) result(p)
      type(run_config_type), intent(in) :: cfg
      type(kind_params_type) :: p
      p%file = cfg%file
      p%nlayer = cfg%shells%nlayer
      p%thickness = cfg%shells%thickness
      p%unit = cfg%shells%unit
      p%mode = cfg%shells%mode
      p%n_ext = cfg%parking%n_ext
      p%min_width = cfg%sieves%min_width(:cfg%sieves%nsieve)
      p%max_width = cfg%sieves%max_width(:cfg%sieves%nsieve)
      p%cache_directory = cache_environment()
   end function kind_params

   !> What the packing needs of the configuration.
   pure function packing_params(cfg) result(p)
      type(run_config_type), intent(in) :: cfg
      type(packing_params_type) :: p
      p%box = cfg%box%length
      p%periodic = cfg%box%periodic
      ! a bounding radius is at least half the particle's width (every caliper dimension lies in
      ! the bounding sphere)
      p%rho_min = 0.5_wp * minval(cfg%sieves%min_width(:cfg%sieves%nsieve))
      p%nlayer = cfg%shells%nlayer
      p%mode = cfg%shells%mode
      p%contact%method = cfg%parking%contact_method
      p%contact%next = cfg%parking%n_ext
      p%contact%nbox = cfg%parking%n_box
      p%contact%certified = cfg%parking%certified
      p%contact%gap = cfg%parking%contact_gap
   end function packing_params

   !> What the attempt sequences of sieve s need of the configuration.
   pure function attempt_params(cfg, ks, s) result(p)
      type(run_config_type), intent(in) :: cfg
      type(kind_set_type), intent(in) :: ks
      integer, intent(in) :: s
      type(attempt_params_type) :: p
      p%seed = cfg%run%seed
      p%sieve = s
      p%max_locations = cfg%parking%max_locations
      p%max_orientations = cfg%parking%max_orientations
      p%max_sizes = cfg%parking%max_sizes
      p%max_shapes = cfg%parking%max_shapes
      p%first_kind = ks%first(s)
      p%nkind = ks%count(s)
      p%nlev = ks%nlev
      p%min_width = cfg%sieves%min_width(s)
      p%max_width = cfg%sieves%max_width(s)
      p%box = cfg%box%length
      p%periodic = cfg%box%periodic
      p%void = cfg%parking%placement == placement%void
   end function attempt_params

   !> What the RSA strategy needs of the configuration and of the caller.
   function rsa_params(cfg, progress_unit, max_batch) result(p)
      type(run_config_type), intent(in) :: cfg
      integer, intent(in), optional :: progress_unit, max_batch
      type(rsa_params_type) :: p
      p%max_failures = cfg%parking%max_failures
      p%overshoot = cfg%parking%last_particle == last_particle%overshoot
      p%carry = cfg%parking%sieve_carry == sieve_carry%rounding
      ! kinds are built when first needed: with one shape and one size per particle, each
      ! particle's kind is its stream's first draw, known before its batch runs (M_sand's two
      ! coarse sieves draw about 8 of their 24 shapes); otherwise a sieve's kinds are built when
      ! it starts
      p%lazy = cfg%parking%max_shapes == 1 .and. cfg%parking%max_sizes == 1
      p%void = cfg%parking%placement == placement%void
      p%nthreads = omp_get_max_threads()
      if (present(max_batch)) p%batch_limit = max(1, max_batch)
      p%vbox = product(cfg%box%length)
      p%nlayer = cfg%shells%nlayer
      if (present(progress_unit)) p%progress_unit = progress_unit
   end function rsa_params

   !> What the dense strategy needs of the configuration.
   function dense_params(cfg) result(p)
      type(run_config_type), intent(in) :: cfg
      type(dense_params_type) :: p
      p%seed = cfg%run%seed
      p%rounds = cfg%parking%dense_rounds
      p%sweeps = cfg%parking%dense_sweeps
      p%target_acceptance = cfg%parking%dense_target_acceptance
      p%time_limit = cfg%parking%dense_time_limit
      p%grow_scale = cfg%parking%dense_grow_scale
      p%overfill = cfg%parking%dense_overfill
      p%max_failures = cfg%parking%dense_max_failures
      p%absolute_shells = cfg%shells%nlayer > 0 .and. cfg%shells%unit == thickness_unit%mm
      p%nthreads = omp_get_max_threads()
   end function dense_params

   !> The model of a packing. The packing's particle arrays move into the model (one at a time,
   !> trimmed to np) and its cell list is freed: at 10^7 particles no two copies of the particles
   !> exist at once. The packing keeps its kinds and np only. Divided arrays: the packing holds
   !> this process' block of the particles (`to_blocks`), which the model takes (the caller sets
   !> `model%first`); the model's np counts every process' particles.
   subroutine fill_model(cfg, pk, result, model)
      type(run_config_type), intent(in) :: cfg
      type(packing_type), intent(inout) :: pk
      type(sieve_result_type), intent(in) :: result(:)
      type(model_type), intent(inout) :: model
      integer :: k, np, s
      real(wp) :: vbox
      np = pk%np
      vbox = product(cfg%box%length)
      model%np = pk%ntotal
      allocate (model%achieved_fraction(size(result)), model%count(size(result)), model%shell_fraction(size(result)))
      do s = 1, size(result)
         model%achieved_fraction(s) = result(s)%vol / vbox
         model%count(s) = result(s)%count
         model%shell_fraction(s) = result(s)%shell_fraction
      end do
      model%box = cfg%box%length
      model%periodic = cfg%box%periodic
      call pk%release()
      if (allocated(pk%rho)) deallocate (pk%rho)
      if (allocated(pk%record)) deallocate (pk%record)
      call take_real2(pk%center, np, model%center)
      call take_real3(pk%rot, np, model%rotation)
      call take_real1(pk%scale, np, model%scale)
      call take_int1(pk%sieve, np, model%sieve)
      allocate (model%shape(np), model%nmax(np), model%shell_thickness(cfg%shells%nlayer, np))
      do k = 1, np
         associate (kd => pk%kinds(pk%kind_of(k)))
            model%shape(k) = kd%shape
            model%nmax(k) = kd%order
            if (cfg%shells%nlayer > 0) then
               model%shell_thickness(:, k) = thickness_to_mm(cfg%shells%thickness, cfg%shells%unit, kd%length, &
                                                             model%scale(k))
            end if
         end associate
      end do
      model%min_width = cfg%sieves%min_width
      model%max_width = cfg%sieves%max_width
      model%target_fraction = cfg%sieves%target_fraction
      model%namelist = cfg%text
      model%resolved = write_config(cfg)
      model%seed = cfg%run%seed
   end subroutine fill_model

   !> a(:, :np) moved into b (a freed): moved whole when it holds np columns, else copied.
   subroutine take_real2(a, np, b)
      real(wp), allocatable, intent(inout) :: a(:, :)
      integer, intent(in) :: np
      real(wp), allocatable, intent(out) :: b(:, :)
      if (size(a, 2) == np) then
         call move_alloc(a, b)
      else
         b = a(:, :np)
         deallocate (a)
      end if
   end subroutine take_real2

   !> a(:, :, :np) moved into b (a freed).
   subroutine take_real3(a, np, b)
      real(wp), allocatable, intent(inout) :: a(:, :, :)
      integer, intent(in) :: np
      real(wp), allocatable, intent(out) :: b(:, :, :)
      if (size(a, 3) == np) then
         call move_alloc(a, b)
      else
         b = a(:, :, :np)
         deallocate (a)
      end if
   end subroutine take_real3

   !> a(:np) moved into b (a freed).
   subroutine take_real1(a, np, b)
      real(wp), allocatable, intent(inout) :: a(:)
      integer, intent(in) :: np
      real(wp), allocatable, intent(out) :: b(:)
      if (size(a) == np) then
         call move_alloc(a, b)
      else
         b = a(:np)
         deallocate (a)
      end if
   end subroutine take_real1

   !> a(:np) moved into b (a freed).
   subroutine take_int1(a, np, b)
      integer, allocatable, intent(inout) :: a(:)
      integer, intent(in) :: np
      integer, allocatable, intent(out) :: b(:)
      if (size(a) == np) then
         call move_alloc(a, b)
      else
         b = a(:np)
         deallocate (a)
      end if
   end subroutine take_int1
end module anm_parking_engine
