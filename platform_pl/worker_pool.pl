:- module(worker_pool,
          [ pool_run/2,                 % +Pool, :Goal
            pool_run/3,                 % +Pool, :Goal, +Options
            pool_signal/3,              % +Pool, +Thread, :Goal
            pool_statistics/2,          % +Pool, -Stats
            pool_retire/0,
            pool_drain/0
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(error), [must_be/2, resource_error/1]).
:- use_module(library(option), [option/3]).
:- use_module(platform_errors, [inert_error/2]).

:- meta_predicate
    pool_run(+, 0),
    pool_run(+, 0, +),
    pool_signal(+, +, 0).

/** <module> Reusable worker threads

Creating a thread costs about half a millisecond in SWI-Prolog 9, which
is more than a whole agent hop on loopback should take. A pool keeps
finished workers waiting on a message queue and hands them the next
goal; when no worker is idle it creates one, up to a maximum. Workers
that stay idle longer than a timeout exit, down to a number kept warm.

Each goal runs in catch/3 with a clean thread-local state as far as this
module is concerned; a goal that leaves thread-local facts behind must
clean them itself (the platform's goals do).

The default idle time is the flag `dfrl_pool_idle` (seconds, default
30), so that a test can make workers expire quickly and check that a
pool whose workers all timed out still takes jobs.
*/

:- create_prolog_flag(dfrl_pool_idle, 30, [type(float), keep(true)]).

:- dynamic
    pool_idle/2,                % Pool, Count
    pool_size/2.                % Pool, Count

:- thread_local
    pool_worker/1,              % Pool: this thread is one of its workers
    retiring/0.                 % this worker exits after its job

%!  pool_run(+Pool, :Goal) is det.
%!  pool_run(+Pool, :Goal, +Options) is det.
%
%   Run Goal in a worker of Pool (an atom; created on first use).
%   Options:
%
%     - max(+N)        most workers of this pool (default 1000)
%     - keep(+N)       idle workers kept warm (default 8)
%     - idle(+Sec)     idle time after which a surplus worker exits
%                      (default: the flag `dfrl_pool_idle`, 30)
%
%   @error resource_error(workers(Pool)) if Pool is at its maximum and
%   every worker is busy.

pool_run(Pool, Goal) :-
    pool_run(Pool, Goal, []).

pool_run(Pool, Goal, Options) :-
    must_be(atom, Pool),
    option(max(Max), Options, 1000),
    option(keep(Keep), Options, 8),
    current_prolog_flag(dfrl_pool_idle, DefaultIdle),
    option(idle(Idle), Options, DefaultIdle),
    with_mutex(dfrl_worker_pool, take_worker(Pool, Max, How)),
    (   How == queue
    ->  pool_queue(Pool, Q),
        thread_send_message(Q, run(Goal))
    ;   How == spawn
    ->  catch(thread_create(worker_start(Pool, Goal, Keep, Idle), _,
                            [detached(true)]),
              E,
              ( with_mutex(dfrl_worker_pool, change(pool_size, Pool, -1)),
                throw(E)
              ))
    ;   resource_error(workers(Pool))
    ).

take_worker(Pool, Max, How) :-
    (   pool_idle(Pool, I), I > 0
    ->  change(pool_idle, Pool, -1),
        How = queue
    ;   ( pool_size(Pool, S) -> true ; S = 0 ),
        S < Max
    ->  change(pool_size, Pool, 1),
        How = spawn
    ;   How = full
    ).

change(Counter, Pool, Delta) :-
    Old =.. [Counter, Pool, N0],
    (   retract(Old)
    ->  true
    ;   N0 = 0
    ),
    N is N0 + Delta,
    New =.. [Counter, Pool, N],
    assertz(New).

pool_queue(Pool, Q) :-
    atom_concat('dfrl_pool_', Pool, Q),
    (   catch(message_queue_property(Q, size(_)), _, fail)
    ->  true
    ;   with_mutex(dfrl_worker_pool,
                   (   catch(message_queue_property(Q, size(_)), _, fail)
                   ->  true
                   ;   message_queue_create(Q, [alias(Q)])
                   ))
    ).

worker_start(Pool, Goal, Keep, Idle) :-
    assertz(pool_worker(Pool)),
    pool_queue(Pool, Q),
    run_goal(Goal),
    after_job(Pool, Q, Keep, Idle).

%   A worker that was told to retire during its job leaves the pool.
after_job(Pool, Q, Keep, Idle) :-
    (   retract(retiring)
    ->  with_mutex(dfrl_worker_pool, change(pool_size, Pool, -1))
    ;   worker_loop(Pool, Q, Keep, Idle)
    ).

worker_loop(Pool, Q, Keep, Idle) :-
    with_mutex(dfrl_worker_pool, change(pool_idle, Pool, 1)),
    worker_wait(Pool, Q, Keep, Idle).

%   thread_get_message/3 *fails* when its timeout expires: that is the
%   idle case, and must not end the worker while the pool still counts
%   it as idle (jobs queued for it would never run).
worker_wait(Pool, Q, Keep, Idle) :-
    (   catch(thread_get_message(Q, Msg0, [timeout(Idle)]), E, interrupted(E, Msg0))
    ->  Msg = Msg0
    ;   Msg = timeout
    ),
    (   Msg = run(Goal)
    ->  run_goal(Goal),
        after_job(Pool, Q, Keep, Idle)
    ;   Msg == exit
    ->  true
    ;   with_mutex(dfrl_worker_pool, may_exit(Pool, Q, Keep, Exit)),
        (   Exit = run(Goal)
        ->  run_goal(Goal),
            after_job(Pool, Q, Keep, Idle)
        ;   Exit == stay
        ->  worker_wait(Pool, Q, Keep, Idle)
        ;   true
        )
    ).

%   Called with the pool mutex held after a timeout. A job may have been
%   queued for us between the timeout and taking the mutex: run it.
may_exit(Pool, Q, Keep, Exit) :-
    (   thread_get_message(Q, run(Goal), [timeout(0)])
    ->  Exit = run(Goal)
    ;   pool_idle(Pool, I),
        I > Keep
    ->  change(pool_idle, Pool, -1),
        change(pool_size, Pool, -1),
        Exit = exit
    ;   Exit = stay
    ).

interrupted('$aborted', _) :- !, throw('$aborted').
interrupted(unwind(A), _) :- !, throw(unwind(A)).
interrupted(_, interrupted).

run_goal(Goal) :-
    catch(( call(Goal) -> true ; true ), E, job_error(E)).

job_error('$dfrl_cancelled') :- !.
job_error(node_stopping) :- !.
job_error('$aborted') :- !, throw('$aborted').
job_error(unwind(A)) :- !, throw(unwind(A)).
job_error(E0) :-                       % a job may run mobile code
    inert_error(E0, E),
    print_message(warning, E).

%!  pool_drain is det.
%
%   Ask every idle worker of every pool to exit, and give them 50 ms to
%   do so (it does not wait for them to finish exiting). Busy workers
%   finish their job first.

pool_drain :-
    with_mutex(dfrl_worker_pool,
               findall(Pool-I, ( retract(pool_idle(Pool, I)), I > 0 ), Idle)),
    forall(member(Pool-I, Idle),
           ( pool_queue(Pool, Q),
             forall(between(1, I, _), thread_send_message(Q, exit)),
             with_mutex(dfrl_worker_pool, change(pool_size, Pool, -I))
           )),
    sleep(0.05).

%!  pool_retire is det.
%
%   Called in a job: the worker running it exits when the job ends
%   instead of waiting for the next one (a thread whose C stack grew
%   deep keeps those pages resident; only its exit gives them back). No
%   effect in a thread that is not a pool worker.

pool_retire :-
    (   pool_worker(_)
    ->  (   retiring
        ->  true
        ;   assertz(retiring)
        )
    ;   true
    ).

%!  pool_signal(+Pool, +Thread, :Goal) is det.
%
%   Run Goal in worker Thread of Pool at its next opportunity (see
%   thread_signal/2). Goal should check that the worker still runs the
%   job it was meant for.

pool_signal(_Pool, Thread, Goal) :-
    catch(thread_signal(Thread, Goal), _, true).

%!  pool_statistics(+Pool, -Stats) is det.
%
%   Stats is pool{size:Size, idle:Idle}.

pool_statistics(Pool, pool{size:Size, idle:Idle}) :-
    ( pool_size(Pool, Size) -> true ; Size = 0 ),
    ( pool_idle(Pool, Idle) -> true ; Idle = 0 ).
